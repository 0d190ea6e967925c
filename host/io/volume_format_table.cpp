// The table of volume formats (one row per format) and what iterates it: detection and the lists
// in messages and help text.
#include "tfmatch/io/volume_format_table.h"

#include <algorithm>
#include <cctype>
#include <fstream>

#include "tfmatch/io/volume_formats.h"

namespace tfm {
namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string join(const std::vector<std::string>& items, std::string_view separator, std::string_view last_separator) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) {
    if (i > 0) out += i + 1 == items.size() ? last_separator : separator;
    out += items[i];
  }
  return out;
}

std::vector<VolumeFormat> make_table() {
  std::vector<VolumeFormat> t;
  t.push_back({
      .name = "netcdf",
      .title = "NetCDF",
      .description = "NetCDF classic, 64-bit offset, CDF-5 and netCDF-4 (HDF5), via netCDF-C",
      .extensions = {".nc", ".nc4", ".cdf", ".netcdf", ".h5", ".hdf5"},
      .sniff = [](std::string_view h) {
        return h.starts_with("CDF\x01") || h.starts_with("CDF\x02") || h.starts_with("CDF\x05") ||
               h.starts_with("\x89HDF");
      },
      .selects = "variable",
      .has_times = true,
      .has_members = true,  // any extra leading dimension
      .count_members = count_netcdf_members,
      .read = read_netcdf_volume,
      .describe = describe_netcdf,
      .open_slabs = open_netcdf_slabs,
  });
  t.push_back({
      .name = "grib",
      .title = "GRIB",
      .description = "GRIB editions 1 and 2, levels stacked into z, via ecCodes",
      .extensions = {".grib", ".grb", ".grib1", ".grib2", ".grb1", ".grb2"},
      .sniff = [](std::string_view h) { return h.starts_with("GRIB"); },
      .selects = "shortName[@typeOfLevel]",
      .has_times = true,
      .has_members = true,  // ensemble number
      .count_members = count_grib_members,
      .read = read_grib_volume,
      .describe = describe_grib,
  });
  t.push_back({
      .name = "vtk",
      .title = "VTK",
      .description = "legacy VTK STRUCTURED_POINTS, ASCII or binary",
      .extensions = {".vtk"},
      .sniff = [](std::string_view h) { return lower(std::string(h)).starts_with("# vtk datafile"); },
      .selects = "array",
      .has_components = true,
      .read = read_vtk_legacy_volume,
      .describe = describe_vtk_legacy,
  });
  t.push_back({
      .name = "vti",
      .title = "VTI",
      .description = "VTK XML ImageData: ASCII, inline base64 or appended arrays, zlib-compressed or not",
      .extensions = {".vti"},
      .sniff = [](std::string_view h) {
        return h.find("<VTKFile") != std::string_view::npos ||
               (h.starts_with("<?xml") && h.find("VTKFile") != std::string_view::npos);
      },
      .selects = "array",
      .has_components = true,
      .read = read_vti_volume,
      .describe = describe_vti,
      .open_slabs = open_vti_slabs,  // appended raw, uncompressed
      .writable = true,  // write_vti (volume_vti.h)
      .concurrent_reads = true,
  });
  t.push_back({
      .name = "nrrd",
      .title = "NRRD",
      .description = "NRRD with attached (.nrrd) or detached (.nhdr + data files) raw, ASCII, hex or gzip data",
      .extensions = {".nrrd", ".nhdr"},
      .sniff = [](std::string_view h) { return h.starts_with("NRRD000"); },
      .has_components = true,  // a 4D NRRD's fastest axis; the reader refuses a name
      .read = read_nrrd_volume,
      .describe = describe_nrrd,
  });
  t.push_back({
      .name = "raw",
      .title = "raw",
      .description = "headerless raw data: name_XxYxZ_type.raw, or --dims and --type",
      .extensions = {".raw"},
      .takes_layout = true,
      .takes_byte_order = true,
      .read = read_raw_volume,
      .describe = describe_raw,
      .open_slabs = open_raw_slabs,
      .writable = true,  // float32, write_raw_float32 (volume_io.h)
      .concurrent_reads = true,
  });
  t.push_back({
      .name = "dat",
      .title = ".dat",
      .description = ".dat descriptor (ObjectFileName, Resolution, Format, ...) naming a raw data file",
      .extensions = {".dat"},
      .takes_byte_order = true,  // the descriptor says the type and size, not the byte order
      .read = read_dat_volume,
      .describe = describe_dat,
      .open_slabs = open_dat_slabs,
      .concurrent_reads = true,
  });
  return t;
}

}  // namespace

const std::vector<VolumeFormat>& volume_formats() {
  static const std::vector<VolumeFormat> table = make_table();
  return table;
}

const VolumeFormat* find_volume_format(const std::filesystem::path& path) {
  const std::string ext = lower(path.extension().string());
  for (const VolumeFormat& f : volume_formats())
    if (std::find(f.extensions.begin(), f.extensions.end(), ext) != f.extensions.end()) return &f;
  // Unknown extension: look at the first bytes.
  std::ifstream in(path, std::ios::binary);
  char head[kVolumeSniffBytes] = {};
  in.read(head, sizeof(head));
  const std::string_view h(head, static_cast<size_t>(std::max<std::streamsize>(in.gcount(), 0)));
  for (const VolumeFormat& f : volume_formats())
    if (f.sniff && f.sniff(h)) return &f;
  return nullptr;
}

std::string detect_volume_format(const std::filesystem::path& path) {
  const VolumeFormat* f = find_volume_format(path);
  return f ? f->name : "";
}

std::string volume_format_titles(bool VolumeFormat::*capability, std::string_view last_separator) {
  std::vector<std::string> titles;
  for (const VolumeFormat& f : volume_formats())
    if (!capability || f.*capability) titles.push_back(f.title);
  return join(titles, ", ", last_separator);
}

std::string volume_format_selectors() {
  std::vector<std::string> items;
  for (const VolumeFormat& f : volume_formats())
    if (f.has_variables()) items.push_back(f.title + " " + f.selects);
  return join(items, " / ", " / ");
}

std::string supported_volume_formats() {
  std::vector<std::string> items;
  for (const VolumeFormat& f : volume_formats()) {
    const std::string exts = join(f.extensions, ", ", ", ");
    items.push_back(f.title == f.extensions.front() ? exts : f.title + " (" + exts + ")");
  }
  return join(items, ", ", ", ");
}

std::string unknown_volume_format_message(const std::filesystem::path& path) {
  return path.string() + ": unknown volume format '" + path.extension().string() +
         "', and its first bytes are none of the known ones (supported: " + supported_volume_formats() + ")";
}

std::string volume_format_help() {
  std::string out;
  for (const VolumeFormat& f : volume_formats()) {
    std::vector<std::string> select;
    if (f.has_variables()) select.push_back(f.selects);
    if (f.has_components) select.push_back("component [k]");
    if (f.has_times) select.push_back("time");
    if (f.has_members) select.push_back("member");
    std::string title = f.title == f.extensions.front() ? "" : f.title;
    title.resize(std::max<size_t>(title.size(), 7), ' ');
    out += "  " + title + " " + join(f.extensions, " ", " ") + "\n          " + f.description;
    if (!select.empty()) out += "; select: " + join(select, ", ", ", ");
    if (f.writable) out += "; also written";
    out += "\n";
  }
  return out;
}

}  // namespace tfm
