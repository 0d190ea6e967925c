// Shared random TFs and synthetic volumes of the tests.
#include "test_data.h"

#include <random>

namespace tfm::test {

TransferFunction random_tf(uint32_t n, uint32_t seed, double c_lo, double c_hi, double a_lo, double a_hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> colour(c_lo, c_hi), opacity(a_lo, a_hi);
  TransferFunction tf;
  tf.rgba.resize(n);
  for (auto& e : tf.rgba) {
    // Sequenced explicitly: the order of draws is part of the data.
    const double r = colour(rng), g = colour(rng), b = colour(rng), a = opacity(rng);
    e = {r, g, b, a};
  }
  return tf;
}

Volume make_volume(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing,
                   const std::string& name, const VoxelValue& value) {
  Volume v;
  v.dims = dims;
  v.spacing = spacing;
  v.name = name;
  v.values.resize(v.voxel_count());
  uint64_t i = 0;
  for (uint64_t z = 0; z < dims[2]; ++z)
    for (uint64_t y = 0; y < dims[1]; ++y)
      for (uint64_t x = 0; x < dims[0]; ++x, ++i) v.values[i] = value(x, y, z, i);
  return v;
}

}  // namespace tfm::test
