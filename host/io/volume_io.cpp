// load_volume(): parses "path:SELECTION", finds the format (extension, else the first bytes) and
// dispatches to its reader.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <fstream>
#include <stdexcept>

#include "volume.h"
#include "volume_formats.h"
#include "volume_io.h"

namespace tfm {
namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// SELECTION = VAR[@LEVELTYPE][,time=N][,member=N] (VAR may be empty: "file.nc:,time=2").
void apply_selection(const std::string& selection, const std::string& file, VolumeOptions& o) {
  size_t comma = selection.find(',');
  // Array names may contain '[' ']' for components; only ",key=N" parts are options.
  std::string var = selection.substr(0, comma);
  if (!var.empty()) o.variable = var;
  while (comma != std::string::npos) {
    size_t next = selection.find(',', comma + 1);
    std::string part = selection.substr(comma + 1, next == std::string::npos ? std::string::npos : next - comma - 1);
    comma = next;
    auto eq = part.find('=');
    std::string key = part.substr(0, eq);
    std::string value = eq == std::string::npos ? "" : part.substr(eq + 1);
    uint64_t n = 0;
    auto [p, ec] = std::from_chars(value.data(), value.data() + value.size(), n);
    if (eq == std::string::npos || value.empty() || ec != std::errc() || p != value.data() + value.size() ||
        (key != "time" && key != "member"))
      throw std::runtime_error(file + ": bad selection ',"+ part + "' (expected ,time=N or ,member=N)");
    (key == "time" ? o.time_index : o.member_index) = n;
  }
}

}  // namespace

VolumeSpec parse_volume_spec(const std::string& spec, const VolumeOptions& defaults) {
  VolumeSpec out{spec, defaults};
  // "file.nc:VAR" selects a variable, unless the whole spec names an existing file.
  if (!std::filesystem::exists(out.path)) {
    auto colon = spec.rfind(':');
    if (colon != std::string::npos && colon > 0) {
      out.path = spec.substr(0, colon);
      apply_selection(spec.substr(colon + 1), out.path.string(), out.options);
    }
  }
  return out;
}

std::string detect_volume_format(const std::filesystem::path& path) {
  const std::string ext = lower(path.extension().string());
  if (ext == ".nc" || ext == ".nc4" || ext == ".cdf" || ext == ".netcdf" || ext == ".h5" || ext == ".hdf5") return "netcdf";
  if (ext == ".grib" || ext == ".grb" || ext == ".grib1" || ext == ".grib2" || ext == ".grb2" || ext == ".grb1") return "grib";
  if (ext == ".vtk") return "vtk";
  if (ext == ".vti") return "vti";
  if (ext == ".nrrd" || ext == ".nhdr") return "nrrd";
  if (ext == ".raw") return "raw";
  if (ext == ".dat") return "dat";
  // Unknown extension: look at the magic bytes.
  std::ifstream in(path, std::ios::binary);
  char head[64] = {};
  in.read(head, sizeof(head));
  const std::string h(head, static_cast<size_t>(in.gcount()));
  if (h.rfind("CDF\x01", 0) == 0 || h.rfind("CDF\x02", 0) == 0 || h.rfind("CDF\x05", 0) == 0 || h.rfind("\x89HDF", 0) == 0)
    return "netcdf";
  if (h.rfind("GRIB", 0) == 0) return "grib";
  if (h.rfind("NRRD000", 0) == 0) return "nrrd";
  if (lower(h).rfind("# vtk datafile", 0) == 0) return "vtk";
  if (h.find("<VTKFile") != std::string::npos || (h.rfind("<?xml", 0) == 0 && h.find("VTKFile") != std::string::npos))
    return "vti";
  return "";
}

Volume load_volume(const std::string& spec, const VolumeOptions& defaults) {
  VolumeSpec s = parse_volume_spec(spec, defaults);
  const std::filesystem::path& path = s.path;
  const VolumeOptions& options = s.options;
  if (!std::filesystem::exists(path)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(path)) throw std::runtime_error(path.string() + ": is a directory, not a volume file");
  const std::string format = detect_volume_format(path);
  // Options that only some formats understand are errors elsewhere, not silently ignored.
  const bool has_times = format == "netcdf" || format == "grib";
  if (!has_times && ((options.time_index && *options.time_index > 0) || (options.member_index && *options.member_index > 0)))
    throw std::runtime_error(path.string() + ": time and member selection apply to NetCDF and GRIB files only");
  if ((format == "raw" || format == "dat") && !options.variable.empty())
    throw std::runtime_error(path.string() + ": a " + format + " file holds one array; remove ':" + options.variable + "' / --var");
  Volume v;
  if (format == "netcdf") v = read_netcdf_volume(path, options);
  else if (format == "grib") v = read_grib_volume(path, options);
  else if (format == "vtk") v = read_vtk_legacy_volume(path, options);
  else if (format == "vti") v = read_vti_volume(path, options);
  else if (format == "nrrd") v = read_nrrd_volume(path, options);
  else if (format == "raw") v = read_raw_volume(path, options);
  else if (format == "dat") v = read_dat_volume(path, options);
  else
    throw std::runtime_error(path.string() + ": unknown volume format '" + path.extension().string() +
                             "' (supported: .nc, .grib/.grib2, .vtk, .vti, .nrrd/.nhdr, .raw, .dat)");
  if (v.voxel_count() == 0 || v.values.size() != v.voxel_count())
    throw std::runtime_error(path.string() + ": the volume is empty");
  return v;
}

}  // namespace tfm
