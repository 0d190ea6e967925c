// Image metrics against scikit-image (tests/host/report/ssim_expected.py), and their edge cases.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "tfmatch/report/metrics.h"

namespace tfm {
namespace {

// Same integer formulas as pixel() in tests/host/report/ssim_expected.py.
int pixel(const std::string& c, int x, int y, int ch, bool second) {
  if (c == "noise") {
    const int a = ((x * 73 + y * 151 + ch * 29) ^ (x * y * 7)) & 255;
    return second ? std::clamp(a + (x * 11 + y * 17 + ch * 5) % 64 - 32, 0, 255) : a;
  }
  if (c == "shifted") {
    const int xs = second ? x + 1 : x;
    return (xs * 6 + y * 2 + ch * 40 + (xs * y) / 9) % 256;
  }
  if (c == "constant") return second ? 110 : 100;
  int v = 40 + 60 * ((x / 4 + y / 3 + ch) % 4);  // "blocks"
  if (second && (x + 2 * y) % 7 == 0) v = 255 - v;
  return v;
}

Image make_image(const std::string& c, uint32_t w, uint32_t h, bool second) {
  Image img(w, h);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x)
      for (int ch = 0; ch < 3; ++ch) img.at(x, y)[ch] = uint8_t(pixel(c, int(x), int(y), ch, second));
  return img;
}

struct Expected {
  const char* name;
  uint32_t width, height;
  double rmse, psnr, ssim;
};

// Printed by tests/host/report/ssim_expected.py with scikit-image 0.19.3 (Debian python3-skimage):
// mean_squared_error -> sqrt, peak_signal_noise_ratio(data_range=255), structural_similarity(
// gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255, channel_axis=-1).
const Expected kExpected[] = {
    {"noise", 37, 29, 17.843735081, 23.1010882724, 0.967986776421},
    {"shifted", 40, 23, 39.1162055449, 16.2836692175, 0.809663164973},
    {"constant", 11, 11, 10, 28.1308036087, 0.995476444092},
    {"blocks", 64, 48, 50.7713131303, 14.0184356891, 0.665237272995},
};

TEST(Metrics, MatchScikitImage) {
  for (const Expected& e : kExpected) {
    SCOPED_TRACE(e.name);
    const ImageMetrics m = compare_images(make_image(e.name, e.width, e.height, false),
                                          make_image(e.name, e.width, e.height, true));
    // The printed values carry 12 significant digits; both sides compute in double.
    EXPECT_NEAR(m.rmse, e.rmse, 1e-8);
    EXPECT_NEAR(m.psnr, e.psnr, 1e-8);
    // The bar is 1e-4; the same algorithm in double agrees to rounding.
    EXPECT_NEAR(m.ssim, e.ssim, 1e-9);
  }
}

TEST(Metrics, ConstantImagesHaveTheClosedFormSsim) {
  // No variance: SSIM = (2 mu_a mu_b + C1) / (mu_a^2 + mu_b^2 + C1), C1 = (0.01 * 255)^2.
  const double c1 = 2.55 * 2.55;
  const double expected = (2.0 * 100 * 110 + c1) / (100.0 * 100 + 110.0 * 110 + c1);
  EXPECT_NEAR(image_ssim(make_image("constant", 23, 17, false), make_image("constant", 23, 17, true)), expected,
              1e-12);
}

TEST(Metrics, IdenticalImagesGiveZeroRmseUnitSsimInfinitePsnr) {
  const Image a = make_image("noise", 37, 29, false);
  const ImageMetrics m = compare_images(a, a);
  EXPECT_EQ(m.rmse, 0.0);
  EXPECT_TRUE(std::isinf(m.psnr) && m.psnr > 0);
  EXPECT_NEAR(m.ssim, 1.0, 1e-12);
  EXPECT_EQ(m.to_json()["psnr"], "inf");
  EXPECT_NE(m.to_string().find("PSNR inf"), std::string::npos) << m.to_string();
}

TEST(Metrics, PsnrFollowsRmse) {
  EXPECT_NEAR(psnr_from_rmse(255.0), 0.0, 1e-12);
  EXPECT_NEAR(psnr_from_rmse(25.5), 20.0, 1e-12);
}

TEST(Metrics, SmallImagesHaveNoSsimButRmse) {
  // Below the 11x11 window scikit-image refuses; tfmatch reports SSIM as missing.
  const Image a = make_image("noise", 10, 30, false), b = make_image("noise", 10, 30, true);
  const ImageMetrics m = compare_images(a, b);
  EXPECT_TRUE(std::isnan(m.ssim));
  EXPECT_GT(m.rmse, 0.0);
  EXPECT_TRUE(m.to_json()["ssim"].is_null());
}

TEST(Metrics, SizeMismatchThrows) {
  EXPECT_THROW(compare_images(Image(12, 12), Image(12, 13)), std::runtime_error);
  EXPECT_THROW(compare_images(Image(), Image()), std::runtime_error);
}

}  // namespace
}  // namespace tfm
