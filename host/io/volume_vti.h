// Writing VTK XML ImageData (.vti) so fields and residual maps open in ParaView; reading is in
// load_volume() (host/io/volume_vti.cpp).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"

namespace tfm {

struct VtiWriteOptions {
  bool compress = true;  // zlib (vtkZLibDataCompressor, 32 KiB blocks), else raw
  // The index of the volume's first voxel in a larger grid whose origin the volume carries: a piece
  // of parallel image data (write_pvti) says its extent in the whole grid's indices.
  std::array<uint64_t, 3> extent_offset{0, 0, 0};
};

// Writes the volumes as Float32 point-data arrays of one ImageData (appended raw data, UInt64
// headers, little-endian), atomically. All volumes must share one grid; the first one's spacing
// is written and its array is the active scalars. NaN stays NaN (ParaView shows it as "NaN
// colour"). Throws std::runtime_error naming `path` on a write failure or differing grids.
void write_vti(const std::filesystem::path& path, const std::vector<std::pair<std::string, const Volume*>>& arrays,
               const VtiWriteOptions& options = {});
// The bytes write_vti writes, for a file sent elsewhere (a download); `name` starts messages.
std::string vti_bytes(const std::vector<std::pair<std::string, const Volume*>>& arrays, const std::string& name,
                      const VtiWriteOptions& options = {});
void write_vti(const std::filesystem::path& path, const Volume& volume, const std::string& array_name,
               const VtiWriteOptions& options = {});

// ParaView's parallel image data: a .pvti file naming the pieces (.vti files written by
// write_vti with their extent_offset, e.g. one per MPI rank) that together cover `whole` (its
// dims, origin and spacing; no values), one Float32 point array `array_name`. Each piece is z-slices
// [z_first, z_last] (inclusive; neighbouring pieces share a slice, so no cell is missing) and its
// `source` is relative to the .pvti's directory. Written atomically.
struct PvtiPiece {
  uint64_t z_first = 0, z_last = 0;
  std::string source;
};
void write_pvti(const std::filesystem::path& path, const Volume& whole, const std::string& array_name,
                const std::vector<PvtiPiece>& pieces);

}  // namespace tfm
