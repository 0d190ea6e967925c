// What a data file holds (`tfmatch info`): its arrays or variables, their grids, types, ranges
// and NaN counts, so a user can pick what to compare.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tfmatch/io/json.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"

namespace tfm {

struct ArrayInfo {
  std::string name;                       // what to write after "file:" to load it
  std::string kind;                       // "variable", "point data", "cell data", "GRIB parameter", ...
  std::string type;                       // element type as stored
  std::string shape;                      // as the file describes it, e.g. "(time=1, lev=14, lat=64, lon=128)"
  std::array<uint64_t, 3> grid{0, 0, 0};  // x, y, z when loaded; all 0 when it is not loadable as a volume
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};  // position of voxel (0, 0, 0) as loaded
  std::vector<std::string> orientation;   // per axis: coordinates, units, world direction (geo grids)
  uint64_t components = 1;
  std::vector<std::string> choices;       // e.g. "time: 4 (--time 0..3)"
  std::vector<std::string> notes;         // units, long name, fill value, packing, ...
  uint64_t values = 0;                    // values examined (all times and members)
  uint64_t nan_count = 0;                 // no-data values among them (NaN, ±Inf, fill values, GRIB missing)
  std::optional<double> min, max;         // finite range
};

struct FileInfo {
  std::string path;
  std::string format;
  std::vector<std::string> notes;
  std::vector<ArrayInfo> arrays;
};

// Describes the file with its format's `describe` (volume_format_table.h), reading every array to
// compute its range. Throws std::runtime_error "<file>: ..." like the readers.
// `options` matter for raw files only (dimensions, type, byte order); a raw file without known
// dimensions is described by its size and the cubes that would fit.
FileInfo describe_file(const std::filesystem::path& path, const VolumeOptions& options = {});
// Describes one selection ("FILE:VAR[,time=N][,member=N]" with `options` as defaults, as
// load_volume reads it): the field as loaded, its grid, axes, range and NaN count at that time and
// member. Throws like load_volume.
FileInfo describe_selection(const std::string& spec, const VolumeOptions& options);
std::string format_file_info(const FileInfo& info);
nlohmann::json file_info_json(const FileInfo& info);

// Adds `n` values to the range and NaN count of `a`.
void accumulate_stats(ArrayInfo& a, const float* values, uint64_t n);

// Each format's describer is declared with its reader in volume_formats.h.

}  // namespace tfm
