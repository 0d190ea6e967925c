// Loading volumes from files (every format of host/io/volume_format_table.h) and writing raw float32.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "tfmatch/model/volume.h"
#include "tfmatch/model/volume_slabs.h"

namespace tfm {

enum class ScalarType { Unknown, UInt8, Int8, UInt16, Int16, UInt32, Int32, Float32, Float64 };

// Parses "uint8", "uint16", "float32", "float64", "int16", ... (also "float", "double", "uchar",
// "ushort"); Unknown when unrecognized.
ScalarType parse_scalar_type(std::string name);
size_t scalar_bytes(ScalarType t);
const char* scalar_type_name(ScalarType t);

// What a user can say about a file beyond its name (the flags of `tfmatch optimize` etc.).
struct VolumeOptions {
  std::optional<std::array<uint64_t, 3>> dims;   // raw: grid size when the name does not say
  ScalarType type = ScalarType::Unknown;         // raw: element type when the name does not say
  bool big_endian = false;                       // raw: byte order
  std::string variable;                          // NetCDF variable / GRIB shortName / VTK array
  std::optional<uint64_t> time_index;            // NetCDF/GRIB: time step
  std::optional<uint64_t> member_index;          // NetCDF: extra dimension; GRIB: ensemble number
  std::string member_dim;                        // NetCDF: the member dimension's name (--member-dim)
};

// Loads a volume. `spec` is a path, optionally followed by ":VAR[@LEVELTYPE][,time=N][,member=N]"
// (overriding `options`; see host/io/volume_formats.h). The format is the file's row of
// volume_format_table.h (by extension, else by the first bytes); selecting a time, member or
// array the format does not have is an error. Throws std::runtime_error whose message starts with
// the file name and says what is wrong (missing file, unknown format, wrong size, ...).
Volume load_volume(const std::string& spec, const VolumeOptions& options = {});

// Two volumes to compare, as load_volume() loads each: read side by side on two threads when
// both files' formats allow it (VolumeFormat::concurrent_reads) and both sizes are known from
// their headers, so that one memory-budget check covers both; else one after the other. Two reads
// from disk into new memory overlap well (41.5 M voxels, 2 x 158 MiB of raw float32, page cache
// dropped: 0.25 s one after the other, 0.15 s side by side on 2 cores). Errors are load_volume()'s;
// when both files fail, the first one's error is thrown, as when they are read in turn.
std::pair<Volume, Volume> load_volume_pair(const std::string& first, const std::string& second,
                                           const VolumeOptions& options = {});

// `spec` (as load_volume() takes it) opened to be read a slab of z-slices at a time, without
// loading it (host/model/volume_slabs.h): raw and .dat files, NetCDF variables (netCDF-C reads any
// hyperslab) and VTI arrays in uncompressed raw appended data. nullptr for any other format or
// encoding. Checks the header and the file's size first; throws as load_volume() does.
std::unique_ptr<VolumeSlabReader> open_volume_slabs(const std::string& spec, const VolumeOptions& options = {});
// open_volume_slabs(), else the volume loaded whole (load_volume()) behind the same interface.
std::unique_ptr<VolumeSlabReader> open_volume_slabs_or_load(const std::string& spec, const VolumeOptions& options = {});

// Readers (host/io/volume_raw.cpp).
Volume read_raw_volume(const std::filesystem::path& path, const VolumeOptions& options);
Volume read_dat_volume(const std::filesystem::path& path, const VolumeOptions& options);

// Writes float32 little-endian raw data, named by the Open SciVis convention if `path` is a
// directory-less stem; returns the path written.
void write_raw_float32(const std::filesystem::path& path, const Volume& v);

}  // namespace tfm
