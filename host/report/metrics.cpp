// RMSE, PSNR and SSIM of 8-bit RGB images.
#include "metrics.h"

#include <cmath>
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

// Mirror index for scipy's 'reflect' mode (d c b a | a b c d | d c b a), any offset.
int reflect(int i, int n) {
  const int period = 2 * n;
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - 1 - i;
}

// Separable Gaussian filter of an h x w plane with reflected borders. Every output is the same
// sum in the same order (k = -r..r) whether its taps need reflecting or not; the interior, where
// none does, runs over whole rows without the index arithmetic (the viewer computes these for
// every camera: 512² took 110 ms a comparison with reflect() on every tap).
std::vector<double> gaussian_filter(const std::vector<double>& in, int w, int h) {
  double weights[2 * kRadius + 1], sum = 0;
  for (int k = -kRadius; k <= kRadius; ++k) sum += weights[k + kRadius] = std::exp(-0.5 * k * k / (1.5 * 1.5));
  for (double& v : weights) v /= sum;
  std::vector<double> tmp(in.size()), out(in.size());
  for (int y = 0; y < h; ++y) {  // along rows (axis 0 first, as scipy does: the order only rounds)
    double* row = tmp.data() + size_t(y) * w;
    if (y >= kRadius && y < h - kRadius) {
      for (int x = 0; x < w; ++x) row[x] = 0.0;
      for (int k = -kRadius; k <= kRadius; ++k) {
        const double* src = in.data() + size_t(y + k) * w;
        const double wk = weights[k + kRadius];
        for (int x = 0; x < w; ++x) row[x] += wk * src[x];
      }
      continue;
    }
    for (int x = 0; x < w; ++x) {
      double acc = 0;
      for (int k = -kRadius; k <= kRadius; ++k) acc += weights[k + kRadius] * in[size_t(reflect(y + k, h)) * w + x];
      row[x] = acc;
    }
  }
  for (int y = 0; y < h; ++y) {
    const double* src = tmp.data() + size_t(y) * w;
    double* dst = out.data() + size_t(y) * w;
    for (int x = 0; x < w; ++x) {
      double acc = 0;
      if (x >= kRadius && x < w - kRadius)
        for (int k = -kRadius; k <= kRadius; ++k) acc += weights[k + kRadius] * src[x + k];
      else
        for (int k = -kRadius; k <= kRadius; ++k) acc += weights[k + kRadius] * src[reflect(x + k, w)];
      dst[x] = acc;
    }
  }
  return out;
}

double channel_ssim(const Image& a, const Image& b, int c) {
  const int w = int(a.width), h = int(a.height);
  const size_t n = size_t(w) * h;
  std::vector<double> x(n), y(n), xx(n), yy(n), xy(n);
  for (size_t i = 0; i < n; ++i) {
    x[i] = a.rgb[3 * i + c];
    y[i] = b.rgb[3 * i + c];
    xx[i] = x[i] * x[i];
    yy[i] = y[i] * y[i];
    xy[i] = x[i] * y[i];
  }
  const auto ux = gaussian_filter(x, w, h), uy = gaussian_filter(y, w, h);
  const auto uxx = gaussian_filter(xx, w, h), uyy = gaussian_filter(yy, w, h), uxy = gaussian_filter(xy, w, h);
  const double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  double total = 0;
  for (int py = kRadius; py < h - kRadius; ++py)
    for (int px = kRadius; px < w - kRadius; ++px) {
      const size_t i = size_t(py) * w + px;
      const double vx = uxx[i] - ux[i] * ux[i], vy = uyy[i] - uy[i] * uy[i], vxy = uxy[i] - ux[i] * uy[i];
      total += ((2 * ux[i] * uy[i] + c1) * (2 * vxy + c2)) /
               ((ux[i] * ux[i] + uy[i] * uy[i] + c1) * (vx + vy + c2));
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
