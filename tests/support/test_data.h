// Test support: the random transfer functions and synthetic volumes the kernel and solver tests
// share, generated from fixed seeds so every run sees the same data.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>

#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm::test {

// N entries with colours uniform in [c_lo, c_hi) and opacity in [a_lo, a_hi) (drawn r, g, b, a
// per entry from one std::mt19937 seeded with `seed`).
TransferFunction random_tf(uint32_t n, uint32_t seed, double c_lo = 0.0, double c_hi = 1.0, double a_lo = 0.0,
                           double a_hi = 1.0);

// A volume of `dims` whose voxel (x, y, z), linear index i, holds value(x, y, z, i).
using VoxelValue = std::function<float(uint64_t x, uint64_t y, uint64_t z, uint64_t i)>;
Volume make_volume(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing,
                   const std::string& name, const VoxelValue& value);

}  // namespace tfm::test
