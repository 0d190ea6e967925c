// A volume read a slab of z-slices at a time (`tfmatch optimize` on volumes larger than memory):
// the interface the file formats implement (open_volume_slabs() of host/io/volume_io.h opens one
// for a file) and the streamed assembly reads (host/solvers/streamed_optimize.h), and an in-memory
// implementation for a volume loaded whole.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "tfmatch/model/volume.h"

namespace tfm {

class VolumeSlabReader {
 public:
  virtual ~VolumeSlabReader() = default;
  // The grid (dims, spacing, origin, name, and NetCDF axis names and coordinates) as
  // load_volume() gives it, without values. (A VTI reader leaves out the axis coordinates
  // tfmatch writes as field data: nothing streamed needs them.)
  const Volume& grid() const { return grid_; }
  uint64_t slice_voxels() const { return grid_.dims[0] * grid_.dims[1]; }
  // Writes z-slices [z0, z0 + nz) into `out` (nz * slice_voxels() floats, x fastest): the values
  // load_volume() would hold there, bit for bit. Throws std::invalid_argument past the grid and
  // std::runtime_error "<file>: ..." when the file cannot be read (truncated since it was opened).
  virtual void read_slices(uint64_t z0, uint64_t nz, float* out) = 0;
  // True when it reads the file as asked; false when the whole volume is in memory.
  virtual bool streams() const { return true; }

 protected:
  void check_slices(uint64_t z0, uint64_t nz) const;
  Volume grid_;
};

// A volume already in memory, as a slab reader (the formats that do not stream).
std::unique_ptr<VolumeSlabReader> slabs_in_memory(Volume volume);

}  // namespace tfm
