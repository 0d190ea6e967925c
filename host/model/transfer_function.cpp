// Transfer-function evaluation and resampling.
#include "tfmatch/model/transfer_function.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>



namespace tfm {

Rgba TransferFunction::eval(double t) const {
  const size_t n = rgba.size();
  double x = std::clamp(t, 0.0, 1.0) * double(n - 1);
  size_t j = std::min<size_t>(static_cast<size_t>(std::floor(x)), n - 2);
  double w = x - double(j);
  Rgba out;
  for (int c = 0; c < 4; ++c) out[c] = (1.0 - w) * rgba[j][c] + w * rgba[j + 1][c];
  return out;
}

void check_table_size(uint64_t n) {
  if (n < 2) throw std::invalid_argument("transfer functions need at least 2 entries");
  if (n > kMaxTableSize)
    throw std::invalid_argument("transfer functions hold at most " + std::to_string(kMaxTableSize) + " entries, not " +
                                std::to_string(n));
}

TransferFunction TransferFunction::resampled(size_t n) const {
  if (n < 2) throw std::invalid_argument("transfer functions need at least 2 entries");
  if (n == rgba.size()) return *this;
  TransferFunction out;
  out.range = range;
  out.rgba.resize(n);
  for (size_t j = 0; j < n; ++j) out.rgba[j] = eval(double(j) / double(n - 1));
  return out;
}

std::vector<float> TransferFunction::as_floats() const {
  std::vector<float> out;
  out.reserve(rgba.size() * 4);
  for (const Rgba& e : rgba)
    for (double c : e) out.push_back(static_cast<float>(c));
  return out;
}


TransferFunction tf_from_color_stops(uint32_t n, std::span<const ColorStop> stops, const std::function<double(double)>& alpha) {
  if (n < 2 || stops.size() < 2) throw std::invalid_argument("tf_from_color_stops: needs 2 or more entries and stops");
  TransferFunction tf;
  tf.rgba.resize(n);
  for (uint32_t j = 0; j < n; ++j) {
    const double t = double(j) / (n - 1);
    size_t k = 0;
    while (k + 2 < stops.size() && t > stops[k + 1].t) ++k;
    const double w = std::clamp((t - stops[k].t) / (stops[k + 1].t - stops[k].t), 0.0, 1.0);
    tf.rgba[j] = {(1 - w) * stops[k].r + w * stops[k + 1].r, (1 - w) * stops[k].g + w * stops[k + 1].g,
                  (1 - w) * stops[k].b + w * stops[k + 1].b, std::clamp(alpha(t), 0.0, 1.0)};
  }
  return tf;
}

}  // namespace tfm
