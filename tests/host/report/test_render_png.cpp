// PNG round trips, compositing over the background, the TF plot's parts, text and panels.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "cli_runner.h"
#include "png_io.h"
#include "tf_plot.h"

namespace tfm {
namespace {

TEST(RenderPng, RoundTripKeepsEveryByte) {
  test::TempDir dir;
  std::mt19937 rng(1);
  for (auto [w, h] : {std::pair{1u, 1u}, std::pair{13u, 7u}, std::pair{300u, 2u}}) {
    Image img(w, h);
    for (auto& b : img.rgb) b = uint8_t(rng());
    write_png(dir / "a.png", img);
    const Image back = read_png(dir / "a.png");
    ASSERT_EQ(back.width, w);
    ASSERT_EQ(back.height, h);
    EXPECT_EQ(back.rgb, img.rgb);
  }
}

TEST(RenderPng, ReadingANonPngNamesTheFile) {
  test::TempDir dir;
  std::ofstream(dir / "x.png") << "not a png";
  try {
    read_png(dir / "x.png");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("x.png"), std::string::npos) << e.what();
  }
  EXPECT_THROW(read_png(dir / "missing.png"), std::runtime_error);
}

TEST(RenderPng, CompositesPremultipliedColourOverTheBackground) {
  RenderedImage r;
  r.width = 2;
  r.height = 1;
  r.rgba = {0.2f, 0.1f, 0.0f, 0.5f, 0.0f, 0.0f, 0.0f, 0.0f};
  r.stop = {3, 0};
  const Image img = composite_over(r, {1.0, 0.0, 0.5});
  // C + (1 - A) * background, rounded: (0.7, 0.1, 0.25) and the background itself.
  EXPECT_EQ(img.at(0, 0)[0], 179);
  EXPECT_EQ(img.at(0, 0)[1], 26);
  EXPECT_EQ(img.at(0, 0)[2], 64);
  EXPECT_EQ(img.at(1, 0)[0], 255);
  EXPECT_EQ(img.at(1, 0)[2], 128);
  EXPECT_EQ(r.samples(), 3u);
}

TEST(RenderPng, TfPlotShowsHistogramCurveAndColourBar) {
  TransferFunction tf;
  for (int j = 0; j < 8; ++j) tf.rgba.push_back({j / 7.0, 0.0, 1.0 - j / 7.0, j < 4 ? 0.0 : 1.0});
  std::vector<float> values(1000, 0.25f);
  values.push_back(NAN);
  TfPlotOptions o;
  o.width = 200;
  o.height = 120;
  const Image img = plot_transfer_function(tf, values, {0, 1}, o);
  ASSERT_EQ(img.width, 200u);
  ASSERT_EQ(img.height, 120u);
  // Find the colour bar: the row whose left end is the TF's first colour (blue).
  int bar_y = -1;
  for (uint32_t y = 0; y < img.height && bar_y < 0; ++y)
    if (img.at(9, y)[2] > 200 && img.at(9, y)[0] < 40) bar_y = int(y);
  ASSERT_GE(bar_y, 0) << "no colour bar";
  EXPECT_GT(img.at(190, bar_y)[0], 200) << "right end of the bar is red";
  // The histogram has one full bar at t = 0.25 (column 8 + 0.25 * 184) and nothing at t = 0.75.
  const int x_full = 8 + 46, x_empty = 8 + 138, y_low = bar_y - 8;
  const uint8_t* full = img.at(x_full, y_low);
  const uint8_t* empty = img.at(x_empty, y_low);
  EXPECT_TRUE(full[0] > 200 && full[2] < 200) << "light yellow histogram bar expected";
  EXPECT_TRUE(empty[0] == 255 && empty[2] == 255) << "no histogram where there is no data";
  // The opacity curve: dark near the top at t = 0.9 (opacity 1), near the bottom at t = 0.2.
  bool dark_top = false;
  for (int y = 0; y < bar_y; ++y) dark_top |= img.at(8 + 166, y)[0] < 80 && y < bar_y / 2;
  EXPECT_TRUE(dark_top) << "opacity curve missing at opacity 1";
  EXPECT_EQ(field_histogram(values, {0, 1}, 4)[1], 1000u);
}

TEST(RenderPng, TextAndPanels) {
  Image img(40, 12);
  const int w = draw_text(img, 1, 1, "Ab1", {0, 0, 0});
  EXPECT_EQ(w, 18);
  EXPECT_EQ(text_width("Ab1"), 17);
  int dark = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3) dark += img.rgb[i] == 0;
  EXPECT_GT(dark, 15);
  const Image p = compose_panels({{Image(30, 20, {255, 0, 0}), "a"}, {Image(30, 20, {0, 0, 255}), "b"},
                                  {Image(10, 10, {0, 255, 0}), "c"}},
                                 2);
  EXPECT_GT(p.width, 60u);
  EXPECT_GT(p.height, 40u);
}

}  // namespace
}  // namespace tfm
