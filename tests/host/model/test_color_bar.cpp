// The colour bar beneath a standalone rendering: the picture kept above it, the TF's colours in
// the bar, labelled values, text that reads on light and dark backgrounds, a title kept to its
// room, nothing on a picture too narrow.
#include <gtest/gtest.h>

#include <cmath>

#include "tfmatch/model/color_bar.h"

namespace tfm {
namespace {

TransferFunction ramp() {
  TransferFunction tf;
  tf.rgba = {{0, 0, 1, 0}, {0, 1, 0, 0.5}, {1, 0, 0, 1}};  // blue, green, red
  return tf;
}

Image checker(uint32_t w, uint32_t h) {
  Image img(w, h);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) img.set(int(x), int(y), ((x / 7 + y / 5) & 1) ? Rgb8{10, 200, 30} : Rgb8{250, 5, 90});
  return img;
}

bool same(const uint8_t* p, Rgb8 c) { return p[0] == c[0] && p[1] == c[1] && p[2] == c[2]; }

// The bar's columns: the run of the strip's middle row whose pixels are neither background nor frame.
struct BarSpan {
  int first = -1, last = -1;
};
BarSpan bar_span(const Image& img, uint32_t bar_row, Rgb8 bg) {
  BarSpan s;
  for (uint32_t x = 0; x < img.width; ++x) {
    const uint8_t* p = img.at(x, bar_row);
    const bool grey = p[0] == p[1] && p[1] == p[2];
    if (same(p, bg) || grey) continue;
    if (s.first < 0) s.first = int(x);
    s.last = int(x);
  }
  return s;
}

TEST(ColorBar, KeepsThePictureAndShowsTheTfColoursBeneathIt) {
  const Image picture = checker(301, 77);
  const std::array<double, 3> white{1, 1, 1};
  const auto out = with_color_bar(picture, ramp(), {250, 310}, "t (K)", white);
  ASSERT_TRUE(out);
  EXPECT_EQ(out->width, 301u);
  EXPECT_EQ(out->height, 77u + kColorBarStripHeight);
  EXPECT_TRUE(std::equal(picture.rgb.begin(), picture.rgb.end(), out->rgb.begin())) << "the picture is untouched";
  // The bar: its columns show T(t) at each column's centre, blue on the left, red on the right.
  const uint32_t row = 77 + 8;
  const BarSpan bar = bar_span(*out, row, {255, 255, 255});
  ASSERT_GE(bar.first, 0);
  const int bar_w = bar.last - bar.first + 1;
  EXPECT_GE(bar_w, 90);
  EXPECT_GT(bar.first, 100) << "the title's room is on the left";
  EXPECT_LE(bar.last, 301 - 8 - 12);
  for (int x = bar.first; x <= bar.last; x += 7) {
    const Rgba c = ramp().eval((x - bar.first + 0.5) / bar_w);
    EXPECT_TRUE(same(out->at(uint32_t(x), row), srgb8(c[0], c[1], c[2]))) << "column " << x;
  }
  // Labels (dark text) beneath the bar, and the title on the left.
  int label_pixels = 0, title_pixels = 0;
  for (uint32_t y = row + 6; y < out->height; ++y)
    for (int x = bar.first - 12; x < int(out->width); ++x) label_pixels += same(out->at(uint32_t(x), y), {40, 40, 40});
  for (uint32_t y = 77; y < out->height; ++y)
    for (int x = 0; x < bar.first - 12; ++x) title_pixels += same(out->at(uint32_t(x), y), {40, 40, 40});
  EXPECT_GT(label_pixels, 3 * 10) << "at least three labelled values (260, 280, 300)";
  EXPECT_GT(title_pixels, 10);
}

TEST(ColorBar, ReadsOnADarkBackgroundAndKeepsTheTitleToItsRoom) {
  const Image picture(240, 20, {0, 0, 0});
  const std::string title = "/data/runs/2026/era5-levels-members.grib:t@isobaricInhPa,time=0,member=0 (K)";
  const auto out = with_color_bar(picture, ramp(), {-1, 1}, title, {0, 0, 0});
  ASSERT_TRUE(out);
  const BarSpan bar = bar_span(*out, 20 + 8, {0, 0, 0});
  ASSERT_GE(bar.first, 0);
  int light = 0, title_pixels = 0;
  for (uint32_t y = 20; y < out->height; ++y)
    for (uint32_t x = 0; x < out->width; ++x) {
      const bool text = same(out->at(x, y), {225, 225, 225});
      light += text;
      if (!text || y >= 20 + 4 + 8) continue;  // labels lie beneath the bar
      // The title (shortened: it is far wider) stays out of the first label's room left of the bar.
      EXPECT_LT(int(x), bar.first - 12) << x << "," << y;
      ++title_pixels;
    }
  EXPECT_GT(light, 20) << "light text on black";
  EXPECT_GT(title_pixels, 20);
}

TEST(ColorBar, NothingOnAPictureTooNarrowAndErrorsForEmptyInputs) {
  EXPECT_FALSE(with_color_bar(Image(kColorBarMinWidth - 1, 50), ramp(), {0, 1}, "x", {1, 1, 1}));
  EXPECT_TRUE(with_color_bar(Image(kColorBarMinWidth, 50), ramp(), {0, 1}, "x", {1, 1, 1}));
  EXPECT_THROW(with_color_bar(Image(200, 50), TransferFunction{}, {0, 1}, "x", {1, 1, 1}), std::invalid_argument);
  EXPECT_THROW(with_color_bar(Image(200, 50), ramp(), {1, 1}, "x", {1, 1, 1}), std::invalid_argument);
}

}  // namespace
}  // namespace tfm
