// The in-memory slab reader and the bounds check every reader shares.
#include "tfmatch/model/volume_slabs.h"

#include <algorithm>
#include <stdexcept>

namespace tfm {

void VolumeSlabReader::check_slices(uint64_t z0, uint64_t nz) const {
  if (nz == 0 || z0 >= grid_.dims[2] || nz > grid_.dims[2] - z0)
    throw std::invalid_argument("read_slices: slices [" + std::to_string(z0) + ", " + std::to_string(z0 + nz) +
                                ") outside the " + std::to_string(grid_.dims[2]) + " of " + grid_.name);
}

namespace {

class InMemorySlabs final : public VolumeSlabReader {
 public:
  explicit InMemorySlabs(Volume v) : values_(std::move(v.values)) {
    grid_ = std::move(v);
    grid_.values.clear();
  }
  void read_slices(uint64_t z0, uint64_t nz, float* out) override {
    check_slices(z0, nz);
    const uint64_t s = slice_voxels();
    std::copy(values_.begin() + std::ptrdiff_t(z0 * s), values_.begin() + std::ptrdiff_t((z0 + nz) * s), out);
  }
  bool streams() const override { return false; }

 private:
  std::vector<float> values_;
};

}  // namespace

std::unique_ptr<VolumeSlabReader> slabs_in_memory(Volume volume) {
  if (volume.values.size() != volume.voxel_count())
    throw std::invalid_argument("slabs_in_memory: " + volume.name + " holds " + std::to_string(volume.values.size()) +
                                " values for " + std::to_string(volume.voxel_count()) + " voxels");
  return std::make_unique<InMemorySlabs>(std::move(volume));
}

}  // namespace tfm
