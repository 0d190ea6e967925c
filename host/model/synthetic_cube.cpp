// The synthetic cube pair.
#include "tfmatch/model/synthetic_cube.h"

#include <cmath>
#include <stdexcept>

namespace tfm {

Volume cube_halves(uint64_t n) {
  Volume v;
  v.dims = {n, n, n};
  v.name = "cube halves";
  v.values.resize(v.voxel_count());
  size_t i = 0;
  for (uint64_t z = 0; z < n; ++z)
    for (uint64_t y = 0; y < n; ++y)
      for (uint64_t x = 0; x < n; ++x) v.values[i++] = 2 * x < n ? 0.0f : 1.0f;
  return v;
}

Volume cube_with_inner_cube(uint64_t n, double inner_fraction) {
  if (!(inner_fraction > 0 && inner_fraction < 1))
    throw std::invalid_argument("cube_with_inner_cube: inner fraction must be in (0, 1)");
  Volume v = cube_halves(n);
  v.name = "cube halves with an inverted inner cube";
  const double centre = 0.5 * double(n - 1), half = 0.5 * inner_fraction * double(n);
  auto inside = [&](uint64_t k) { return std::abs(double(k) - centre) < half; };
  size_t i = 0;
  for (uint64_t z = 0; z < n; ++z)
    for (uint64_t y = 0; y < n; ++y)
      for (uint64_t x = 0; x < n; ++x, ++i)
        if (inside(x) && inside(y) && inside(z)) v.values[i] = 1.0f - v.values[i];
  return v;
}

TransferFunction blue_to_red_tf(uint32_t n, double opacity) {
  if (n < 2) throw std::invalid_argument("blue_to_red_tf: at least 2 entries");
  TransferFunction tf;
  tf.rgba.resize(n);
  for (uint32_t j = 0; j < n; ++j) {
    const double t = double(j) / double(n - 1);
    tf.rgba[j] = {t, 0.0, 1.0 - t, opacity};
  }
  tf.range = FieldRange{0.0, 1.0};
  return tf;
}

}  // namespace tfm
