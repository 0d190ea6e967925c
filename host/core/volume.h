// Scalar volumes on regular grids (x fastest, then y, then z); files: host/io/volume_io.h.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tfm {

struct Volume {
  std::array<uint64_t, 3> dims{0, 0, 0};          // x, y, z
  std::array<double, 3> spacing{1.0, 1.0, 1.0};   // physical size of a voxel step
  std::vector<float> values;                      // NaN = no data
  std::string name;                               // where it came from, for messages

  uint64_t voxel_count() const { return dims[0] * dims[1] * dims[2]; }
  float at(uint64_t x, uint64_t y, uint64_t z) const { return values[(z * dims[1] + y) * dims[0] + x]; }
};

// Throws std::runtime_error when the two volumes are not on one grid.
void require_same_grid(const Volume& a, const Volume& b);

}  // namespace tfm
