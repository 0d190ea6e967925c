// Writing VTK XML ImageData (.vti) so fields and residual maps open in ParaView; reading is in
// load_volume() (host/volume_vti.cpp).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "volume.h"
#include "volume_io.h"

namespace tfm {

struct VtiWriteOptions {
  bool compress = true;  // zlib (vtkZLibDataCompressor, 32 KiB blocks), else raw
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

}  // namespace tfm
