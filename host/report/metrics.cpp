// RMSE, PSNR and SSIM of 8-bit RGB images.
#include "tfmatch/report/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <future>
#include <limits>
#include <stdexcept>
#include <vector>

namespace tfm {
namespace {

constexpr int kRadius = 5;  // int(3.5 * 1.5 + 0.5): scipy's truncation of a sigma 1.5 Gaussian

void require_same_size(const Image& a, const Image& b) {
  if (a.width == 0 || a.height == 0 || b.width == 0 || b.height == 0)
    throw std::runtime_error("image metrics: empty image");
  if (a.width != b.width || a.height != b.height)
    throw std::runtime_error("image metrics: images differ in size (" + std::to_string(a.width) + "x" +
                             std::to_string(a.height) + " vs " + std::to_string(b.width) + "x" +
                             std::to_string(b.height) + ")");
}

// SSIM of one channel, a row at a time. The mean runs over the pixels at least kRadius from every
// edge (scikit-image crops the border), and there every tap of the 11x11 Gaussian lies inside the
// image: the border's filtered values (scipy's 'reflect' mode) never count, so none is computed.
// Each output row needs the five planes x, y, x², y², xy filtered along columns over its 11 input
// rows, then along the row; the products are exact in double (at most 255²), so they are formed
// as the taps read them. Memory: five rows of doubles, not five planes (a 30000² image wanted
// 24 GB); every value is the same sum in the same order as a whole-plane filter (axis 0 first,
// as scipy: the order only rounds), and the mean sums the rows in order, so the same bits.
double channel_ssim(const Image& a, const Image& b, int c) {
  const int w = int(a.width), h = int(a.height);
  double weights[2 * kRadius + 1], sum = 0;
  for (int k = -kRadius; k <= kRadius; ++k) sum += weights[k + kRadius] = std::exp(-0.5 * k * k / (1.5 * 1.5));
  for (double& v : weights) v /= sum;
  const double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  std::vector<double> col(5 * size_t(w));  // the five planes filtered along columns, one row
  double* const cx = col.data();
  double* const cy = cx + w;
  double* const cxx = cy + w;
  double* const cyy = cxx + w;
  double* const cxy = cyy + w;
  double total = 0;
  for (int py = kRadius; py < h - kRadius; ++py) {
    std::fill(col.begin(), col.end(), 0.0);
    for (int k = -kRadius; k <= kRadius; ++k) {
      const uint8_t* ra = a.rgb.data() + 3 * size_t(py + k) * w + c;
      const uint8_t* rb = b.rgb.data() + 3 * size_t(py + k) * w + c;
      const double wk = weights[k + kRadius];
      for (int x = 0; x < w; ++x) {
        const double vx = ra[3 * x], vy = rb[3 * x];
        cx[x] += wk * vx;
        cy[x] += wk * vy;
        cxx[x] += wk * (vx * vx);
        cyy[x] += wk * (vy * vy);
        cxy[x] += wk * (vx * vy);
      }
    }
    for (int px = kRadius; px < w - kRadius; ++px) {
      double ux = 0, uy = 0, uxx = 0, uyy = 0, uxy = 0;
      for (int k = -kRadius; k <= kRadius; ++k) {
        const double wk = weights[k + kRadius];
        ux += wk * cx[px + k];
        uy += wk * cy[px + k];
        uxx += wk * cxx[px + k];
        uyy += wk * cyy[px + k];
        uxy += wk * cxy[px + k];
      }
      const double vx = uxx - ux * ux, vy = uyy - uy * uy, vxy = uxy - ux * uy;
      total += ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
    }
  }
  return total / double((w - 2 * kRadius) * (h - 2 * kRadius));
}

std::string format(double v, const char* fmt) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

}  // namespace

double image_rmse(const Image& a, const Image& b) {
  require_same_size(a, b);
  double sum = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    const double d = double(a.rgb[i]) - double(b.rgb[i]);
    sum += d * d;
  }
  return std::sqrt(sum / double(a.rgb.size()));
}

double psnr_from_rmse(double rmse) {
  return rmse == 0 ? std::numeric_limits<double>::infinity() : 20.0 * std::log10(255.0 / rmse);
}

double image_ssim(const Image& a, const Image& b) {
  require_same_size(a, b);
  if (a.width < 2 * kRadius + 1 || a.height < 2 * kRadius + 1) return std::numeric_limits<double>::quiet_NaN();
  // The channels side by side (independent; summed in the same order after).
  auto green = std::async(std::launch::async, [&] { return channel_ssim(a, b, 1); });
  auto blue = std::async(std::launch::async, [&] { return channel_ssim(a, b, 2); });
  const double red = channel_ssim(a, b, 0);
  return (red + green.get() + blue.get()) / 3.0;
}

ImageMetrics compare_images(const Image& a, const Image& b) {
  ImageMetrics m;
  m.rmse = image_rmse(a, b);
  m.psnr = psnr_from_rmse(m.rmse);
  m.ssim = image_ssim(a, b);
  return m;
}

nlohmann::json ImageMetrics::to_json() const {
  nlohmann::json j;
  j["rmse"] = rmse;
  j["psnr"] = std::isinf(psnr) ? nlohmann::json("inf") : nlohmann::json(psnr);
  j["ssim"] = std::isnan(ssim) ? nlohmann::json(nullptr) : nlohmann::json(ssim);
  return j;
}

std::string ImageMetrics::to_string() const {
  return "RMSE " + format(rmse, "%.4f") + "  PSNR " + (std::isinf(psnr) ? std::string("inf") : format(psnr, "%.3f")) +
         " dB  SSIM " + (std::isnan(ssim) ? std::string("n/a") : format(ssim, "%.5f"));
}

}  // namespace tfm
