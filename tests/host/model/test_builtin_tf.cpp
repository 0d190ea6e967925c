// Built-in transfer functions: entries against the published colour values (typed here from the
// sources, not from colormap_tables.cpp), the linear-RGB convention, opacity shapes, name parsing
// and the view's default choice.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/model/color_spaces.h"

namespace tfm {
namespace {

// IEC 61966-2-1, written out here so that the test does not trust the code under test for it.
double srgb_to_linear_light(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

// Entry `e` holds the linear-RGB form of the sRGB colour `hex` (#rrggbb) to within `tol_255` of
// an 8-bit sRGB step: each channel must lie between the linear values of hex -/+ tol_255.
void expect_srgb(const Rgba& e, const char* hex, double tol_255, const std::string& where) {
  unsigned r = 0, g = 0, b = 0;
  ASSERT_EQ(std::sscanf(hex, "#%02x%02x%02x", &r, &g, &b), 3) << hex;
  const unsigned want[3] = {r, g, b};
  for (int c = 0; c < 3; ++c) {
    const double s = want[c] / 255.0, lo = srgb_to_linear_light(std::max(0.0, s - tol_255 / 255.0)),
                 hi = srgb_to_linear_light(std::min(1.0, s + tol_255 / 255.0));
    EXPECT_TRUE(e[c] >= lo && e[c] <= hi) << where << " channel " << c << ": " << e[c] << " (sRGB "
                                          << linear_to_srgb(e[c]) * 255 << "), published " << hex << " = " << want[c];
  }
}

TransferFunction table(const std::string& name, size_t n) { return builtin_transfer_function({name, OpacityShape::Ramp}, n); }

// Published entries of matplotlib's 256-entry tables (index k at t = k/255) as matplotlib prints
// them with to_hex: viridis(0) #440154, (64) #3b528b, (128) #21918c, (191) #5cc863, (255) #fde725.
// The built-in keeps every 8th entry and interpolates between them, so a skipped entry (191) may
// differ by up to 1.7/255; 2/255 is the tolerance.
TEST(BuiltinTf, ViridisAndInfernoMatchMatplotlibsPublishedTables) {
  const TransferFunction v = table("viridis", 256), i = table("inferno", 256);
  const struct {
    size_t k;
    const char *viridis, *inferno;
  } published[] = {{0, "#440154", "#000004"},
                   {64, "#3b528b", "#57106e"},
                   {128, "#21918c", "#bc3754"},
                   {191, "#5cc863", "#f98c0a"},
                   {255, "#fde725", "#fcffa4"}};
  for (const auto& p : published) {
    expect_srgb(v.rgba[p.k], p.viridis, 2.0, "viridis entry " + std::to_string(p.k));
    expect_srgb(i.rgba[p.k], p.inferno, 2.0, "inferno entry " + std::to_string(p.k));
  }
  // The default 64-entry table samples the same map: its middle lies between entries 127 and 128.
  const TransferFunction v64 = table("viridis", 64);
  expect_srgb(v64.eval(0.5), "#21908d", 2.0, "viridis(0.5) of 64 entries");
  EXPECT_FALSE(v64.range.has_value());
}

// Moreland (2009): blue (59,76,192), a grey-white centre (221,221,221), red (180,4,38); between
// them his Msh interpolation, which color_spaces.h implements for ParaView's "Diverging" space.
TEST(BuiltinTf, CoolWarmMatchesMorelandsEndsCentreAndMshInterpolation) {
  const TransferFunction cw = table("cool-warm", 65);
  expect_srgb(cw.rgba[0], "#3b4cc0", 0.5, "cool-warm at 0");   // (59,76,192)
  expect_srgb(cw.rgba[32], "#dddddd", 0.5, "cool-warm at 0.5");  // (221,221,221)
  expect_srgb(cw.rgba[64], "#b40426", 0.5, "cool-warm at 1");  // (180,4,38)
  const Rgb blue{59 / 255.0, 76 / 255.0, 192 / 255.0}, red{180 / 255.0, 4 / 255.0, 38 / 255.0};
  for (size_t j = 0; j < cw.size(); j += 4) {
    const Rgb msh = interpolate_color(blue, red, double(j) / 64.0, ColorInterpolation::Diverging);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(linear_to_srgb(cw.rgba[j][c]) * 255, msh[c] * 255, 2.0) << "entry " << j << " channel " << c;
  }
}

// ColorBrewer RdBu (11 classes), reversed: #053061 ... #f7f7f7 ... #67001f, one class per 0.1.
TEST(BuiltinTf, DivergingIsColorBrewerRdBuBlueToRed) {
  const TransferFunction d = table("diverging", 11);
  const char* classes[] = {"#053061", "#2166ac", "#4393c3", "#92c5de", "#d1e5f0", "#f7f7f7",
                           "#fddbc7", "#f4a582", "#d6604d", "#b2182b", "#67001f"};
  for (size_t k = 0; k < 11; ++k) expect_srgb(d.rgba[k], classes[k], 0.01, "diverging class " + std::to_string(k));
}

// Black to white in equal sRGB steps: entry j's linear value is the sRGB value j/(N-1) decoded.
TEST(BuiltinTf, GreyIsEvenInSrgbAndStoredLinear) {
  const TransferFunction g = table("grey", 5);
  for (size_t j = 0; j < 5; ++j)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(g.rgba[j][c], srgb_to_linear_light(j / 4.0), 1e-12) << j;
  EXPECT_NEAR(g.rgba[2][0], 0.21404114048223255, 1e-12);  // sRGB 0.5: not 0.5 in linear light
}

TEST(BuiltinTf, OpacityShapesAndEachMapsDefault) {
  const double ts[] = {0.0, 0.25, 0.5, 0.75, 1.0};
  const double ramp[] = {0, 0.25, 0.5, 0.75, 1}, tent[] = {0, 0.5, 1, 0.5, 0}, vee[] = {1, 0.5, 0, 0.5, 1};
  for (int i = 0; i < 5; ++i) {
    EXPECT_DOUBLE_EQ(opacity_at(OpacityShape::Ramp, ts[i]), ramp[i]);
    EXPECT_DOUBLE_EQ(opacity_at(OpacityShape::Flat, ts[i]), 0.5);
    EXPECT_DOUBLE_EQ(opacity_at(OpacityShape::Tent, ts[i]), tent[i]);
    EXPECT_DOUBLE_EQ(opacity_at(OpacityShape::Vee, ts[i]), vee[i]);
  }
  EXPECT_EQ(default_opacity_shape("viridis"), OpacityShape::Ramp);
  EXPECT_EQ(default_opacity_shape("inferno"), OpacityShape::Ramp);
  EXPECT_EQ(default_opacity_shape("grey"), OpacityShape::Ramp);
  EXPECT_EQ(default_opacity_shape("cool-warm"), OpacityShape::Vee);
  EXPECT_EQ(default_opacity_shape("diverging"), OpacityShape::Vee);
  // The table's opacity is the shape at each node; colours do not depend on it.
  const TransferFunction tent5 = builtin_transfer_function({"inferno", OpacityShape::Tent}, 5);
  const TransferFunction ramp5 = builtin_transfer_function({"inferno", OpacityShape::Ramp}, 5);
  for (int j = 0; j < 5; ++j) {
    EXPECT_DOUBLE_EQ(tent5.rgba[j][3], tent[j]);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(tent5.rgba[j][c], ramp5.rgba[j][c]);
  }
}

TEST(BuiltinTf, NamesAndOptionsParse) {
  EXPECT_EQ(builtin_tf_names(), (std::vector<std::string>{"viridis", "inferno", "cool-warm", "grey", "diverging"}));
  const auto v = parse_builtin_tf("viridis");
  ASSERT_TRUE(v);
  EXPECT_EQ(v->name, "viridis");
  EXPECT_EQ(v->opacity, OpacityShape::Ramp);
  const auto d = parse_builtin_tf("Diverging,opacity=TENT");  // names and options ignore case
  ASSERT_TRUE(d);
  EXPECT_EQ(d->name, "diverging");
  EXPECT_EQ(d->opacity, OpacityShape::Tent);
  EXPECT_EQ(parse_builtin_tf("cool-warm,opacity=flat")->opacity, OpacityShape::Flat);
  EXPECT_EQ(parse_builtin_tf("grey,opacity=vee")->opacity, OpacityShape::Vee);
  // Not a built-in name: maybe a file, so no error here.
  for (const char* other : {"tf.json", "viridis.json", "viridis:preset", "", "magma"}) EXPECT_FALSE(parse_builtin_tf(other)) << other;
  // A built-in name with a bad option is an error that says what is expected.
  for (const char* bad : {"viridis,opacity=round", "viridis,alpha=ramp", "viridis,"}) {
    try {
      parse_builtin_tf(bad);
      ADD_FAILURE() << bad << " parsed";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("opacity=ramp|flat|tent|vee"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(builtin_transfer_function({"viridis", OpacityShape::Ramp}, 1), std::invalid_argument);
  EXPECT_THROW(builtin_transfer_function({"magma", OpacityShape::Ramp}, 8), std::invalid_argument);
  const std::string syntax = builtin_tf_syntax();
  for (const std::string& name : builtin_tf_names()) EXPECT_NE(syntax.find(name), std::string::npos) << syntax;
}

TEST(BuiltinTf, ViewDefaultIsDivergingOnlyForRangesSpanningZero) {
  EXPECT_EQ(default_builtin_tf({-0.4, 0.9}).name, "diverging");
  EXPECT_EQ(default_builtin_tf({-0.4, 0.9}).opacity, OpacityShape::Vee);
  EXPECT_EQ(default_builtin_tf({0.0, 1.0}).name, "viridis");  // zero at an end: not signed data
  EXPECT_EQ(default_builtin_tf({-3.0, 0.0}).name, "viridis");
  EXPECT_EQ(default_builtin_tf({40.0, 340.0}).name, "viridis");
  EXPECT_EQ(default_builtin_tf({40.0, 340.0}).opacity, OpacityShape::Ramp);
}

// A diverging map's neutral middle is said where a range of the field's puts it away from 0.
TEST(BuiltinTf, DivergingMiddleNoteSaysWhereTheMiddleLies) {
  const std::string note = diverging_middle_note({"cool-warm", OpacityShape::Vee}, {-20.0, 60.0}, "--range");
  EXPECT_NE(note.find("'cool-warm' is laid over [-20, 60]"), std::string::npos) << note;
  EXPECT_NE(note.find("middle lies at 20, not at 0"), std::string::npos) << note;
  EXPECT_NE(note.find("--range -60,60 centres it"), std::string::npos) << note;
  EXPECT_NE(diverging_middle_note({"diverging", OpacityShape::Flat}, {-5.0, 1.0}, "--ref-range").find("--ref-range -5,5"),
            std::string::npos);
  EXPECT_EQ(diverging_middle_note({"diverging", OpacityShape::Vee}, {-2.0, 2.0}, "--range"), "");  // centred
  EXPECT_EQ(diverging_middle_note({"diverging", OpacityShape::Vee}, {-2.0, 2.003}, "--range"), "");  // within 0.1 %
  EXPECT_EQ(diverging_middle_note({"diverging", OpacityShape::Vee}, {1.0, 9.0}, "--range"), "");   // not signed
  EXPECT_EQ(diverging_middle_note({"viridis", OpacityShape::Ramp}, {-20.0, 60.0}, "--range"), "");  // not diverging
  for (const std::string& name : builtin_tf_names())
    EXPECT_EQ(diverging_builtin_tf(name), name == "diverging" || name == "cool-warm") << name;
}

}  // namespace
}  // namespace tfm
