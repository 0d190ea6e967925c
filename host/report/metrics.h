// Image similarity on the CPU in double precision: RMSE and PSNR on the 0..255 scale, and SSIM
// as in Wang et al. 2004 configured like scikit-image's structural_similarity(gaussian_weights=
// True, sigma=1.5, use_sample_covariance=False, data_range=255, channel_axis=-1).
#pragma once

#include <string>

#include "tfmatch/io/json.h"
#include "tfmatch/model/image.h"

namespace tfm {

struct ImageMetrics {
  double rmse = 0.0;  // over all RGB values, 0..255 scale
  double psnr = 0.0;  // dB, +infinity for identical images
  double ssim = 0.0;  // mean over channels; NaN when an image side is below 11 pixels

  // {"rmse": x, "psnr": x or "inf", "ssim": x or null}: JSON has no infinity, so an infinite
  // PSNR (identical images) is the string "inf", as cond(M) is elsewhere in tfmatch.
  nlohmann::json to_json() const;
  // "RMSE 3.21  PSNR 37.99 dB  SSIM 0.9876" ("inf" / "n/a" where they apply).
  std::string to_string() const;
};

// Throws std::runtime_error when the sizes differ or an image is empty.
ImageMetrics compare_images(const Image& a, const Image& b);

double image_rmse(const Image& a, const Image& b);
// 20 log10(255 / RMSE); +infinity when RMSE is 0.
double psnr_from_rmse(double rmse);
// Mean SSIM over the R, G, B channels: 11x11 Gaussian window (sigma 1.5, truncated at 3.5
// sigma), K1 = 0.01, K2 = 0.03, L = 255, population (co)variances, mirror-reflected borders,
// averaged over pixels at least 5 from every border. NaN if width or height < 11.
double image_ssim(const Image& a, const Image& b);

}  // namespace tfm
