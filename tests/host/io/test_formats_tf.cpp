// Transfer functions from other tools: the framework's XML (colour data modes, sRGB vs linear
// blending), ParaView presets (colour spaces, opacity midpoint/sharpness, ranges), tfmatch JSON,
// round trips table -> file -> table, and malformed files.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "formats_test_util.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/tf_json.h"
#include "tfmatch/model/builtin_tf.h"

namespace tfm {
namespace {

using formats_test::expect_error;

// sRGB 0.5 in linear light: ((0.5 + 0.055) / 1.055)^2.4 (IEC 61966-2-1).
const double kHalfSrgbLinear = std::pow(0.555 / 1.055, 2.4);

std::string xml(const std::string& interp, const std::string& color_data, const std::string& points) {
  return "<TransferFunction colorspace=\"sRGB\"" + (interp.empty() ? "" : " interpolation_colorspace=\"" + interp + "\"") +
         ">\n<OpacityPoints>\n<OpacityPoint position=\"0\" opacity=\"0\"/>\n<OpacityPoint position=\"1\" opacity=\"1\"/>\n"
         "</OpacityPoints>\n<ColorPoints" + (color_data.empty() ? "" : " color_data=\"" + color_data + "\"") + ">\n" + points +
         "</ColorPoints>\n</TransferFunction>\n";
}

TransferFunction parse(const std::string& text, size_t n = 0) {
  return parse_transfer_function(text, "mem.tf", TfReadOptions{n, ""});
}

TEST(TfFormats, SrgbCurve) {
  EXPECT_NEAR(srgb_to_linear(0.5), 0.21404114048223255, 1e-15);
  EXPECT_NEAR(linear_to_srgb(0.21404114048223255), 0.5, 1e-15);
  EXPECT_EQ(srgb_to_linear(0.04), 0.04 / 12.92);
  for (double c = 0; c <= 1.0; c += 0.01) EXPECT_NEAR(linear_to_srgb(srgb_to_linear(c)), c, 1e-14);
}

TEST(TfFormats, XmlBlendsInSrgbOrLinearAndReadsEveryColorDataMode) {
  const std::string bw = "<ColorPoint position=\"0\" r=\"0\" g=\"0\" b=\"0\"/>\n<ColorPoint position=\"1\" r=\"255\" g=\"255\" b=\"255\"/>\n";
  // Default blending is sRGB: the midpoint is sRGB 0.5, stored as linear.
  TransferFunction s = parse(xml("", "", bw), 3);
  ASSERT_EQ(s.size(), 3u);
  EXPECT_NEAR(s.rgba[1][0], kHalfSrgbLinear, 1e-12);
  EXPECT_NEAR(s.rgba[1][3], 0.5, 1e-15);
  EXPECT_EQ(s.rgba[2], (Rgba{1, 1, 1, 1}));
  // Linear RGB blending: the midpoint is linear 0.5.
  EXPECT_NEAR(parse(xml("Linear RGB", "ubyte", bw), 3).rgba[1][1], 0.5, 1e-12);
  auto one = [&](const std::string& mode, const std::string& r) {
    return parse(xml("", mode, "<ColorPoint position=\"0.5\" r=\"" + r + "\" g=\"0\" b=\"0\"/>\n"), 2).rgba[0][0];
  };
  EXPECT_NEAR(one("ushort", "65535"), 1.0, 1e-15);
  EXPECT_NEAR(one("float", "0.5"), kHalfSrgbLinear, 1e-12);
  EXPECT_NEAR(one("float_255", "127.5"), kHalfSrgbLinear, 1e-12);
  EXPECT_NEAR(one("ubyte", "300"), 1.0, 1e-15);  // clamped like the framework does, with a note
  std::vector<std::string> notes;
  parse_transfer_function(xml("", "", "<ColorPoint position=\"0.5\" r=\"300\" g=\"-2\" b=\"0\"/>\n"), "f.xml", {2, ""}, &notes);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("f.xml: 2 opacity or colour values outside [0,1] clamped to it"), std::string::npos) << notes[0];
  notes.clear();
  parse_transfer_function(xml("", "", bw), "f.xml", {2, ""}, &notes);
  EXPECT_TRUE(notes.empty());
  // Positions outside [0, 1] are clamped as well, and said (they were not).
  parse_transfer_function(xml("", "", "<ColorPoint position=\"-0.5\" r=\"0\" g=\"0\" b=\"0\"/>\n"
                                      "<ColorPoint position=\"1.5\" r=\"255\" g=\"0\" b=\"0\"/>\n"),
                          "f.xml", {2, ""}, &notes);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("f.xml: 2 point positions outside [0,1] clamped to it"), std::string::npos) << notes[0];
  // Points in any order; a single colour point is constant.
  TransferFunction u = parse(xml("", "", "<ColorPoint position=\"1\" r=\"255\" g=\"0\" b=\"0\"/>\n"
                                         "<ColorPoint position=\"0\" r=\"0\" g=\"0\" b=\"255\"/>\n"), 2);
  EXPECT_EQ(u.rgba[0], (Rgba{0, 0, 1, 0}));
  EXPECT_EQ(u.rgba[1], (Rgba{1, 0, 0, 1}));
}

// tfmatch JSON tables are linear RGB; one that says it is sRGB is converted entry by entry (the
// "colorspace" field was ignored before, so an sRGB table was read as linear).
TEST(TfFormats, JsonTablesAreLinearOrConvertedFromSrgb) {
  const std::string rows = "\"rgba\": [[0.5,0.25,1,0.5],[0,1,0.04045,1]]}";
  const TransferFunction linear = parse("{\"colorspace\": \"linear-rgb\", " + rows);
  EXPECT_EQ(linear.rgba[0], (Rgba{0.5, 0.25, 1, 0.5}));
  EXPECT_EQ(parse("{" + rows).rgba, linear.rgba);  // the default
  const TransferFunction srgb = parse("{\"colorspace\": \"srgb\", " + rows);
  EXPECT_NEAR(srgb.rgba[0][0], kHalfSrgbLinear, 1e-12);
  EXPECT_NEAR(srgb.rgba[0][1], std::pow((0.25 + 0.055) / 1.055, 2.4), 1e-12);
  EXPECT_EQ(srgb.rgba[0][2], 1.0);
  EXPECT_EQ(srgb.rgba[0][3], 0.5);  // opacity is not a colour
  EXPECT_NEAR(srgb.rgba[1][2], 0.04045 / 12.92, 1e-12);  // the linear segment's end
}

TEST(TfFormats, TableSizeFollowsTheControlPoints) {
  ControlPointTf cp;
  cp.opacity = {{0, 0}, {0.25, 1}, {1, 0}};
  cp.color = {{0, {0, 0, 0}}, {0.75, {1, 1, 1}}};
  EXPECT_EQ(auto_table_size(cp), 257u);  // points on quarters: 4 * 64 + 1
  cp.opacity[1].position = 1.0 / 63;
  cp.color[1].position = 5.0 / 63;
  EXPECT_EQ(auto_table_size(cp), 316u);  // 63 * 5 + 1
  cp.opacity[1].position = std::sqrt(2.0) / 3.0;  // on no grid k/d with d <= 4096
  EXPECT_EQ(auto_table_size(cp), 256u);
  // Tables larger than 4097 entries keep their size through control points (an XML or ParaView
  // file of a --tf-size 5000 fit read back as 256 entries); many points on no grid: 4 a point.
  for (size_t n : {4098u, 5000u, 65536u}) {
    TransferFunction tf;
    tf.rgba.resize(n);
    for (size_t j = 0; j < n; ++j) tf.rgba[j] = {double(j % 7) / 6, 0.5, double(j % 3) / 2, double(j % 5) / 4};
    const ControlPointTf points = control_points_from_table(tf);
    EXPECT_EQ(auto_table_size(points), n);
    const TransferFunction back = table_from_control_points(points);
    ASSERT_EQ(back.size(), n);
    for (size_t j = 0; j < n; j += 997) EXPECT_NEAR(back.rgba[j][3], tf.rgba[j][3], 1e-12) << n << " " << j;
  }
  cp.opacity.clear();
  for (int k = 0; k < 1000; ++k) cp.opacity.push_back({std::sqrt(2.0) * k / 1415.0, 0.5});
  EXPECT_EQ(auto_table_size(cp), 4 * 1001u);  // the colour point at 0.75 too (0 is one of them)
}

TransferFunction random_table(size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  TransferFunction tf;
  tf.rgba.resize(n);
  for (auto& e : tf.rgba)
    for (double& c : e) c = u(rng);
  tf.rgba[3] = {0, 0, 0, 0};
  tf.rgba[4] = {1, 1, 1, 1};
  tf.range = FieldRange{-3.5, 12.25};
  return tf;
}

TEST(TfFormats, TablesRoundTripThroughXmlAndParaView) {
  for (size_t n : {2u, 13u, 64u}) {
    const TransferFunction tf = random_table(std::max<size_t>(n, 5), unsigned(n));
    for (const std::string& text : {tf_to_xml(tf), tf_to_paraview_json(tf, "rt")}) {
      TransferFunction back = parse(text);
      ASSERT_TRUE(back.range);
      EXPECT_EQ(back.range->lo, -3.5);
      EXPECT_EQ(back.range->hi, 12.25);
      // Nodes of the original are nodes of the (refined) table read back.
      TransferFunction again = back.resampled(tf.size());
      // Tolerance: the sRGB curve and back in double precision, plus position arithmetic.
      for (size_t j = 0; j < tf.size(); ++j)
        for (int c = 0; c < 4; ++c) ASSERT_NEAR(again.rgba[j][c], tf.rgba[j][c], 1e-12) << j << " " << c;
      // The XML blends in linear RGB like the table: equal between nodes too.
      if (text[0] == '<') {
        for (double t = 0; t <= 1.0; t += 0.0137) EXPECT_NEAR(back.eval(t)[1], tf.eval(t)[1], 1e-12);
      } else {
        // The preset says its table size: the same table comes back, not a refined one.
        EXPECT_EQ(back.size(), tf.size());
        // ParaView blends the points' sRGB values (what a fine table read from them holds):
        // within half an 8-bit level of the table's linear blend between its nodes too.
        const TransferFunction paraview = parse_transfer_function(text, "rt.json", {4001, ""});
        double worst = 0;
        for (size_t k = 0; k < paraview.size(); ++k)
          for (int c = 0; c < 4; ++c)
            worst = std::max(worst, std::abs(paraview.rgba[k][c] - tf.eval(double(k) / 4000)[c]));
        EXPECT_LE(worst, 1.0 / 512 + 1e-9) << n;
      }
    }
  }
  const TransferFunction tf = random_table(8, 1);
  EXPECT_EQ(parse(tf_to_json(tf), 0).rgba, tf.rgba);
  EXPECT_EQ(parse(tf_to_json(tf), 15).size(), 15u);
  // A range of exactly [0, 1] and no range are told apart in every format (a ParaView preset's
  // points span [0, 1] in both cases: its "tfmatchRange" key says which).
  TransferFunction unit = tf;
  unit.range = FieldRange{0.0, 1.0};
  TransferFunction none = tf;
  none.range.reset();
  for (const auto& write : {tf_to_json, tf_to_xml}) {
    EXPECT_TRUE(parse(write(unit)).range);
    EXPECT_FALSE(parse(write(none)).range);
  }
  const TransferFunction unit_back = parse(tf_to_paraview_json(unit, "u"));
  ASSERT_TRUE(unit_back.range);
  EXPECT_EQ(unit_back.range->lo, 0.0);
  EXPECT_EQ(unit_back.range->hi, 1.0);
  EXPECT_FALSE(parse(tf_to_paraview_json(none, "n")).range);
  // Black to white in two entries, the widest gap between the two blends (0.29 midway).
  TransferFunction ramp;
  ramp.rgba = {{0, 0, 0, 0}, {1, 1, 1, 1}};
  const std::string ramp_preset = tf_to_paraview_json(ramp, "ramp");
  EXPECT_EQ(parse(ramp_preset).rgba, ramp.rgba);
  const TransferFunction ramp_paraview = parse_transfer_function(ramp_preset, "ramp.json", {1025, ""});
  for (size_t k = 0; k < ramp_paraview.size(); ++k)
    ASSERT_NEAR(ramp_paraview.rgba[k][1], double(k) / 1024, 1.0 / 512 + 1e-9) << k;
}

std::string preset(const std::string& space, const std::string& rgb, const std::string& points, const std::string& name = "p") {
  return "{\"Name\": \"" + name + "\", \"ColorSpace\": \"" + space + "\", \"RGBPoints\": [" + rgb + "]" +
         (points.empty() ? "" : ", \"Points\": [" + points + "]") + "}";
}

TEST(TfFormats, ParaViewColourSpacesOpacityShapeAndRange) {
  // Range from the points' span; opacity midpoint 0.25: the value is halfway at a quarter.
  TransferFunction a = parse(preset("RGB", "-1, 0,0,0, 3, 1,1,1", "-1, 0, 0.25, 0, 3, 1, 0.5, 0"), 5);
  ASSERT_TRUE(a.range);
  EXPECT_EQ(a.range->lo, -1.0);
  EXPECT_EQ(a.range->hi, 3.0);
  EXPECT_NEAR(a.rgba[1][3], 0.5, 1e-12);
  EXPECT_NEAR(a.rgba[2][0], kHalfSrgbLinear, 1e-12);  // ParaView "RGB" blends the stored values
  // Sharpness 1: a step at the midpoint.
  TransferFunction st = parse(preset("RGB", "0, 0,0,0, 1, 1,1,1", "0, 0, 0.5, 1, 1, 1, 0.5, 0"), 5);
  EXPECT_EQ(st.rgba[1][3], 0.0);
  EXPECT_EQ(st.rgba[3][3], 1.0);
  EXPECT_FALSE(st.range);  // [0,1]: a normalized preset
  expect_error([] { parse(preset("RGB", "0, 0,0,0, 1, 1,1,1", "").insert(1, "\"tfmatchRange\": [2, 1], ")); },
               {"tfmatchRange", "lo < hi"});
  // Step colour space: the left point's colour.
  EXPECT_EQ(parse(preset("Step", "0, 1,0,0, 1, 0,0,1", "0,1,0.5,0, 1,1,0.5,0"), 3).rgba[1][0], 1.0);
  // Diverging: distinct saturated ends pass through Msh (88, 0, 0): L* = 88, a neutral grey of
  // luminance ((88 + 16) / 116)^3 in linear light.
  const double grey = std::pow(104.0 / 116.0, 3);
  TransferFunction d = parse(preset("Diverging", "0, 0.23,0.299,0.754, 1, 0.706,0.016,0.15", "0,1,0.5,0, 1,1,0.5,0"), 3);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(d.rgba[1][c], grey, 2e-3);  // tolerance: rounded D65/matrix constants
  // Lab between black and white: L* = 50.
  TransferFunction lab = parse(preset("Lab", "0, 0,0,0, 1, 1,1,1", "0,1,0.5,0, 1,1,0.5,0"), 3);
  EXPECT_NEAR(lab.rgba[1][1], std::pow(66.0 / 116.0, 3), 2e-3);
  // HSV from red to blue takes the shorter arc, through magenta.
  TransferFunction hsv = parse(preset("HSV", "0, 1,0,0, 1, 0,0,1", "0,1,0.5,0, 1,1,0.5,0"), 3);
  EXPECT_NEAR(hsv.rgba[1][0], 1.0, 1e-12);
  EXPECT_NEAR(hsv.rgba[1][1], 0.0, 1e-12);
  EXPECT_NEAR(hsv.rgba[1][2], 1.0, 1e-12);
  // Several presets: by name, else the first, saying so; no opacity points: a ramp, with a note.
  const std::string many = "[" + preset("RGB", "0,0,0,0, 1,1,1,1", "", "gray") + "," +
                           preset("RGB", "0,1,0,0, 1,1,0,0", "0,0.5,0.5,0, 1,0.5,0.5,0", "red") + "]";
  EXPECT_EQ(parse_transfer_function(many, "m.json", {0, "red"}).rgba[0][3], 0.5);
  std::vector<std::string> notes;
  TransferFunction g = parse_transfer_function(many, "m.json", {3, ""}, &notes);
  EXPECT_EQ(g.rgba[1][3], 0.5);
  ASSERT_EQ(notes.size(), 2u);
  EXPECT_NE(notes[0].find("m.json: 2 presets (gray, red); using the first, 'gray' (FILE:NAME picks one)"), std::string::npos)
      << notes[0];
  EXPECT_NE(notes[1].find("ramp"), std::string::npos);
  notes.clear();
  parse_transfer_function(many, "m.json", {3, "red"}, &notes);
  EXPECT_TRUE(notes.empty()) << notes.front();  // the one named: nothing to say
  expect_error([&] { parse_transfer_function(many, "m.json", {0, "blue"}); }, {"m.json", "no preset named 'blue'", "gray, red"});
}

TEST(TfFormats, MalformedFilesGiveClearErrors) {
  const std::string pt = "<ColorPoint position=\"0\" r=\"0\" g=\"0\" b=\"0\"/>\n";
  expect_error([&] { parse("<TransferFunction><OpacityPoints>"); }, {"mem.tf", "not well-formed XML"});
  expect_error([&] { parse("<Colormap/>"); }, {"<Colormap>", "not <TransferFunction>"});
  expect_error([&] { parse("<TransferFunction><ColorPoints>" + pt + "</ColorPoints></TransferFunction>"); }, {"no <OpacityPoint>"});
  expect_error([&] { parse(xml("", "", "")); }, {"no <ColorPoint>"});
  expect_error([&] { parse(xml("", "", "<ColorPoint position=\"x\" r=\"0\" g=\"0\" b=\"0\"/>")); }, {"line", "'position'", "'x'"});
  expect_error([&] { parse(xml("", "", "<ColorPoint position=\"0\" r=\"0\" g=\"nan\" b=\"0\"/>")); }, {"finite number in 'g'"});
  expect_error([&] { parse(xml("", "rgb16", pt)); }, {"unknown color_data 'rgb16'"});
  expect_error([&] { parse(xml("HSL", "", pt)); }, {"unknown interpolation_colorspace 'HSL'"});
  std::string half_range = xml("", "", pt);
  half_range.insert(half_range.find('>'), " range_min=\"2\"");
  expect_error([&] { parse(half_range); }, {"mem.tf", "range_min without range_max"});
  expect_error([&] { parse(preset("RGB", "0,0,0", "")); }, {"\"RGBPoints\" must be an array of 4 numbers per point"});
  expect_error([&] { parse(preset("RGB", "0,0,0,2, 1,0,0,0", "")); }, {"colour 2 outside [0,1]"});
  expect_error([&] { parse(preset("RGB", "0.5,0,0,0, 0.5,1,1,1", "")); }, {"one position"});
  expect_error([&] { parse(preset("XYZ", "0,0,0,0, 1,1,1,1", "")); }, {"unknown ColorSpace 'XYZ'"});
  expect_error([&] { parse("{\"ColorSpace\": 5, \"RGBPoints\": [0,0,0,0, 1,1,1,1]}"); },
               {"\"ColorSpace\" must be a name", "not 5"});
  expect_error([&] { parse("{\"tfmatchTableSize\": 1, \"RGBPoints\": [0,0,0,0, 1,1,1,1]}"); },
               {"\"tfmatchTableSize\" must be a whole number from 2 to 65536"});
  expect_error([&] { parse("{\"Name\": \"x\"}"); }, {"no \"RGBPoints\""});
  // An object of neither kind is not called a preset.
  expect_error([&] { parse("{\"range\": [0, 1]}"); },
               {"mem.tf: a JSON object with neither \"rgba\" (a tfmatch table) nor \"RGBPoints\""});
  expect_error([&] { parse("[1, 2"); }, {"not valid JSON"});
  expect_error([&] { parse("{\"rgba\": [[0,0,0,0],[1,1,1"); }, {"mem.tf", "not valid JSON", "line 1, column"});
  expect_error([&] { parse("{\"rgba\": [[0,0,0,0],[1.0000001,1,1,1]]}"); }, {"row 1 has value 1.0000001 outside"});
  expect_error([&] { parse("{\"rgba\": [[0,0,0,-1e-9],[1,1,1,1]]}"); }, {"row 0 has value -1e-09 outside"});
  expect_error([&] { parse("{\"rgba\": [[0,0,0,0]]}"); }, {"at least 2 entries"});
  expect_error([&] { parse("{\"colorspace\": \"cmyk\", \"rgba\": [[0,0,0,0],[1,1,1,1]]}"); },
               {"unknown \"colorspace\" \"cmyk\" (linear-rgb, the default, or srgb)"});
  expect_error([&] { parse("{\"rgba\": [[0,0,0,0],[1,1,1,1]], \"rgba\": [[1,0,0,0],[1,1,1,1]]}"); },
               {"mem.tf", "the key \"rgba\" appears more than once"});
  // FILE:NAME picks a preset; a file of one TF has none, and the name is not silently dropped.
  expect_error([&] { parse_transfer_function("{\"rgba\": [[0,0,0,0],[1,1,1,1]]}", "t.json", {0, "a"}); },
               {"t.json: ':a' names a preset of a ParaView preset file", "tfmatch JSON table"});
  expect_error([&] { parse_transfer_function(xml("", "", pt), "t.xml", {0, "a"}); }, {"t.xml: ':a'", "an XML file"});
  // Nesting beyond what a TF has is refused before a document is built (a 60 MB file of brackets
  // took the parser past 2.9 GB); brackets inside strings do not count.
  expect_error([&] { parse(std::string(100000, '[') + std::string(100000, ']')); },
               {"mem.tf", "nested more than 8 levels deep"});
  EXPECT_EQ(parse("{\"rgba\": [[0,0,0,0],[1,1,1,1]], \"note\": \"[[[[[[[[[[ \\\" {{{{\"}").size(), 2u);
  expect_error([&] { parse("hello"); }, {"not a transfer function"});
  expect_error([&] { parse(""); }, {"empty transfer function file"});
}

TEST(TfFormats, WriteDispatchesByExtensionAndReadsBack) {
  formats_test::TempDir dir;
  const TransferFunction tf = random_table(16, 7);
  for (const std::string name : {"a.json", "b.xml", "c.paraview.json"}) {
    write_transfer_function(dir / name, tf);
    TransferFunction back = read_transfer_function(dir / name).resampled(16);
    for (size_t j = 0; j < 16; ++j)
      for (int c = 0; c < 4; ++c) ASSERT_NEAR(back.rgba[j][c], tf.rgba[j][c], 1e-12) << name;
  }
  EXPECT_NE(formats_test::read_bytes(dir / "c.paraview.json").find("\"Name\": \"c\""), std::string::npos);
  // A table larger than any kernel takes is refused on reading, naming the file (convert-tf
  // passed it on to fail later, nameless).
  std::string big = "{\"rgba\": [";
  for (size_t j = 0; j <= kMaxTableSize; ++j) big += (j ? ",[0,0,0,0]" : "[0,0,0,0]");
  formats_test::write_bytes(dir / "big.json", big + "]}");
  expect_error([&] { read_transfer_function(dir / "big.json"); }, {"big.json", "65537 entries", "at most 65536"});
  expect_error([&] { write_transfer_function(dir / "d.txt", tf); }, {"d.txt", "unknown transfer function format"});
  // FILE:PRESET names a preset; the table comes back at its own 16 entries ("tfmatchTableSize").
  EXPECT_EQ(read_transfer_function((dir / "c.paraview.json").string() + ":c").size(), 16u);
  expect_error([&] { read_transfer_function((dir / "c.paraview.json").string() + ":nope"); }, {"no preset named 'nope'"});
  // A built-in name is a file's only when a file has it: a folder named viridis (an output folder)
  // leaves the built-in map as it is; a file of that name is read.
  const std::filesystem::path before = std::filesystem::current_path();
  std::filesystem::current_path(dir.path());
  std::filesystem::create_directory("viridis");
  EXPECT_EQ(read_transfer_function("viridis").size(), kDefaultBuiltinTfSize);
  write_transfer_function("grey.json", random_table(5, 3));
  std::filesystem::rename("grey.json", "grey");
  EXPECT_EQ(read_transfer_function("grey").size(), 5u);
  std::filesystem::current_path(before);
}

}  // namespace
}  // namespace tfm
