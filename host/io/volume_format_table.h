// The one table of volume file formats. Detection (extension, then first bytes), load_volume(),
// `tfmatch info`, the "supported formats" message and the CLI's help text all iterate it, so a new
// format is its reader file(s) plus one row in volume_format_table.cpp.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/model/volume_slabs.h"

namespace tfm {

struct VolumeFormat {
  std::string name;                     // what detect_volume_format() returns: "netcdf", "vti", ...
  std::string title;                    // in lists for people: "NetCDF", "VTI", ".dat"
  std::string description;              // one line: variants, encodings, what the file holds
  std::vector<std::string> extensions;  // lower case, with the dot; the first is the usual one
  // True when the first bytes of a file (at most kVolumeSniffBytes) are this format's; nullptr
  // when only the extension identifies it.
  bool (*sniff)(std::string_view head) = nullptr;
  // What "FILE:SELECTOR" / --var names, e.g. "variable", "shortName[@typeOfLevel]"; empty when the
  // file holds one array.
  std::string selects;
  bool has_components = false;  // "NAME[k]" / "[k]" picks a component of a vector array
  bool has_times = false;       // ",time=N" / --time
  bool has_members = false;     // ",member=N" / --member
  bool takes_layout = false;     // --dims and --type describe its files (they have no header)
  bool takes_byte_order = false; // --big-endian describes its files
  // With has_members: how many members the array `options` select has (1 when it has no member
  // axis); an ensemble is read member by member (host/io/ensemble_io.h).
  uint64_t (*count_members)(const std::filesystem::path& path, const VolumeOptions& options) = nullptr;
  // Reads one volume; throws std::runtime_error "<file>: <what is wrong>".
  Volume (*read)(const std::filesystem::path& path, const VolumeOptions& options) = nullptr;
  // What `tfmatch info` prints for the file; options matter where the file does not describe itself.
  FileInfo (*describe)(const std::filesystem::path& path, const VolumeOptions& options) = nullptr;
  // Opens the file to be read a slab of z-slices at a time (`optimize` on volumes larger than
  // memory), checking its header and size first; returns nullptr when this file's encoding does
  // not allow it (compressed, text): it is loaded whole. nullptr here: the format never streams.
  std::unique_ptr<VolumeSlabReader> (*open_slabs)(const std::filesystem::path& path, const VolumeOptions& options) = nullptr;
  bool writable = false;  // tfmatch writes this format too (convert-volume, residual maps)
  // read() and open_slabs() may run in two threads at once: the reader is tfmatch's own code over
  // thread-safe libraries (zlib, expat). load_volume_pair() reads two such files side by side.
  // Not netCDF-C or ecCodes, which are not thread-safe.
  bool concurrent_reads = false;

  bool has_variables() const { return !selects.empty(); }
};

// How many leading bytes the sniffers see.
constexpr size_t kVolumeSniffBytes = 64;

// Every format, in the order they are listed and tried.
const std::vector<VolumeFormat>& volume_formats();

// The format of a file: the first row listing its extension (case-insensitive), else the first
// row whose sniffer accepts its first bytes; nullptr when neither says.
const VolumeFormat* find_volume_format(const std::filesystem::path& path);
// find_volume_format()'s name, or "" when unknown.
std::string detect_volume_format(const std::filesystem::path& path);

// The titles of the formats that have `capability` (all when nullptr), joined with ", " and
// `last_separator` before the last: "NetCDF and GRIB", "NetCDF, GRIB, ..., raw or .dat".
std::string volume_format_titles(bool VolumeFormat::*capability = nullptr, std::string_view last_separator = " and ");
// What "FILE:SELECTOR" names in each format that has variables: "NetCDF variable / GRIB ...".
std::string volume_format_selectors();
// Every format with its extensions, for error messages: "NetCDF (.nc, .nc4, ...), GRIB (...), ...".
std::string supported_volume_formats();
// The error for a file no row recognizes: "<file>: unknown volume format '.ext' (supported: ...)".
std::string unknown_volume_format_message(const std::filesystem::path& path);
// Two lines per format (title, extensions; description, what can be selected), for help text.
std::string volume_format_help();

}  // namespace tfm
