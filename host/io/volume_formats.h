// The volume-format readers and describers behind the format table (volume_format_table.h) and
// what they share: element decoding (including 64-bit integers, which ScalarType lacks),
// array/component selection, checked sizes, file bytes.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume_slabs.h"

namespace tfm {

// Element types of the formats read here (a superset of ScalarType).
enum class ElementType { UInt8, Int8, UInt16, Int16, UInt32, Int32, UInt64, Int64, Float32, Float64 };
size_t element_bytes(ElementType t);
const char* element_type_name(ElementType t);

// Whether a number written as text (ASCII data) is a value of type `t`: any number for the float
// types; for the integer types a whole number within the type's range (999 is no unsigned_char:
// read as it stands, it gave a uint8 field a range of [1, 999]).
bool fits_element_type(double v, ElementType t);

// Decodes `count` elements stored with the given byte order into floats (64-bit integers and
// doubles are rounded to the nearest float). `dst` may equal `src` for four-byte types.
void decode_elements(const char* src, uint64_t count, ElementType type, bool big_endian, float* dst);

// Upper bound on the voxels of any grid a reader accepts: header sizes are checked against it
// (and against the bytes really present) before anything is allocated.
constexpr uint64_t kMaxVoxels = uint64_t(1) << 40;
// zlib cannot expand data by more than about 1032:1, so a header that promises more output than
// 1032 * compressed + 1 KiB is lying; readers check this before allocating the output.
constexpr uint64_t kMaxDeflateRatio = 1032;

// dims[0]*dims[1]*dims[2]; throws "<file>: ..." when a dimension is 0 or the product exceeds
// kMaxVoxels (so it cannot overflow).
uint64_t checked_voxel_count(const std::array<uint64_t, 3>& dims, const std::string& file);
// a*b, or throws "<file>: <what> overflows" when it exceeds `limit`.
uint64_t checked_mul(uint64_t a, uint64_t b, uint64_t limit, const std::string& file, const std::string& what);

// Reads `n` bytes at `offset` of a file (on disk or in memory) into `out`; false past the end.
// What checks of a file's structure use before a library parses it.
using ByteReader = std::function<bool(uint64_t offset, uint64_t n, char* out)>;

// Whole file in memory; throws "<file>: cannot open (...)".
std::string read_file_bytes(const std::filesystem::path& path);

// An array name as a user writes it after "file:": "NAME", "NAME[k]" (component k) or "[k]"
// (component k of the default array).
struct ArraySelector {
  std::string name;
  std::optional<uint64_t> component;
};
ArraySelector parse_array_selector(const std::string& text, const std::string& file);

// The array `sel` names among a VTK-family file's arrays (each with `name` and `section`), or,
// without a name, the one of lowest `rank(array)` (file order breaks ties). Field-data arrays are
// not on the grid: naming one is an error. Throws std::runtime_error naming `file` and listing
// the grid arrays when nothing matches.
template <class Array, class Rank>
const Array& pick_grid_array(const std::vector<Array>& arrays, const ArraySelector& sel, Rank rank,
                             const std::string& file) {
  const Array* pick = nullptr;
  std::string names;
  for (const Array& a : arrays) {
    if (a.section == "field data") {
      if (a.name == sel.name)
        throw std::runtime_error(file + ": no array '" + a.name + "' on the grid: '" + a.name +
                                 "' is field data, not on the grid");
      continue;
    }
    names += (names.empty() ? "" : ", ") + a.name;
    if (sel.name.empty() ? (!pick || rank(a) < rank(*pick)) : (a.name == sel.name && !pick)) pick = &a;
  }
  if (!pick) {
    if (sel.name.empty()) throw std::runtime_error(file + ": no arrays on the grid");
    throw std::runtime_error(file + ": no array '" + sel.name + "' (arrays: " + (names.empty() ? "none" : names) + ")");
  }
  return *pick;
}

// From `tuples` interleaved tuples of `components` values: component k, or (no component given)
// the values themselves for one component and the Euclidean magnitude for several. Throws
// "<what>: ..." when k is out of range.
std::vector<float> select_component(std::vector<float> interleaved, uint64_t components,
                                    std::optional<uint64_t> component, const std::string& what);
// One tuple's value under select_component()'s rule (`component` < `components`, unchecked).
float reduce_tuple(const float* tuple, uint64_t components, std::optional<uint64_t> component);

// The position of an array's first value in VTK's image data: the grid's origin for point data,
// the centre of the first cell (origin + spacing / 2) for cell data.
std::array<double, 3> origin_of(const std::array<double, 3>& origin, const std::array<double, 3>& spacing,
                                const std::string& section);

// Parses one number from a text token (locale-independent, accepts a leading '+', nan, inf).
std::optional<double> parse_number(std::string_view token);

// "path:SELECTION" as given on the command line. SELECTION is VAR[@LEVELTYPE][,time=N][,member=N];
// what it names overrides `defaults`. The whole spec is a path when that file exists.
struct VolumeSpec {
  std::filesystem::path path;
  VolumeOptions options;
};
VolumeSpec parse_volume_spec(const std::string& spec, const VolumeOptions& defaults);

// ---- per format (host/io/volume_*.cpp): the `read` and `describe` of its row of
// volume_format_table.h; each throws std::runtime_error "<file>: <what is wrong>" ----
// (read_raw_volume and read_dat_volume are in volume_io.h.)
Volume read_netcdf_volume(const std::filesystem::path& path, const VolumeOptions& options);
Volume read_grib_volume(const std::filesystem::path& path, const VolumeOptions& options);
Volume read_vtk_legacy_volume(const std::filesystem::path& path, const VolumeOptions& options);
Volume read_vti_volume(const std::filesystem::path& path, const VolumeOptions& options);
Volume read_nrrd_volume(const std::filesystem::path& path, const VolumeOptions& options);
// How many members `options` select from (the row's count_members).
uint64_t count_netcdf_members(const std::filesystem::path& path, const VolumeOptions& options);
uint64_t count_grib_members(const std::filesystem::path& path, const VolumeOptions& options);
// What `tfmatch info` says; only raw and .dat use `options`.
FileInfo describe_netcdf(const std::filesystem::path& path, const VolumeOptions& options);
FileInfo describe_grib(const std::filesystem::path& path, const VolumeOptions& options);
FileInfo describe_vtk_legacy(const std::filesystem::path& path, const VolumeOptions& options);
FileInfo describe_vti(const std::filesystem::path& path, const VolumeOptions& options);
FileInfo describe_nrrd(const std::filesystem::path& path, const VolumeOptions& options);
FileInfo describe_raw(const std::filesystem::path& path, const VolumeOptions& options);
FileInfo describe_dat(const std::filesystem::path& path, const VolumeOptions& options);

// The row's open_slabs (host/model/volume_slabs.h): nullptr when the file cannot stream.
std::unique_ptr<VolumeSlabReader> open_raw_slabs(const std::filesystem::path& path, const VolumeOptions& options);
std::unique_ptr<VolumeSlabReader> open_dat_slabs(const std::filesystem::path& path, const VolumeOptions& options);
std::unique_ptr<VolumeSlabReader> open_netcdf_slabs(const std::filesystem::path& path, const VolumeOptions& options);
std::unique_ptr<VolumeSlabReader> open_vti_slabs(const std::filesystem::path& path, const VolumeOptions& options);

// In-memory parsers (what the fuzz targets drive). `name` prefixes every error message.
Volume parse_vtk_legacy(std::string_view bytes, const std::string& name, const VolumeOptions& options);
Volume parse_vti(std::string_view bytes, const std::string& name, const VolumeOptions& options);
// NetCDF and GRIB from memory (netCDF-C's nc_open_mem, ecCodes through fmemopen), as from a file.
Volume parse_netcdf(std::string_view bytes, const std::string& name, const VolumeOptions& options);
FileInfo describe_netcdf_bytes(std::string_view bytes, const std::string& name);
Volume parse_grib(std::string_view bytes, const std::string& name, const VolumeOptions& options);
FileInfo describe_grib_bytes(std::string_view bytes, const std::string& name);
// `open_data_file(relative_name)` returns the bytes of a detached data file (NRRD "data file").
using DataFileLoader = std::function<std::string(const std::string& relative_name)>;
Volume parse_nrrd(std::string_view bytes, const std::string& name, const VolumeOptions& options,
                  const DataFileLoader& open_data_file);

// The .dat descriptor (host/io/volume_raw.cpp), parsed from text.
struct DatDescriptor {
  std::string object_file;
  std::array<uint64_t, 3> dims{0, 0, 0};
  std::string format;
  ScalarType type = ScalarType::Unknown;
  std::array<double, 3> spacing{1, 1, 1};
  bool big_endian = false;
};
DatDescriptor parse_dat_descriptor(std::string_view text, const std::string& name, bool big_endian_default);

}  // namespace tfm
