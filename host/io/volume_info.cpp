// describe_file(): dispatches to the format's describer; text and JSON renderings of the result.
#include "volume_info.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "volume_formats.h"
#include "volume_io.h"

namespace tfm {

void accumulate_stats(ArrayInfo& a, const float* v, uint64_t n) {
  a.values += n;
  for (uint64_t i = 0; i < n; ++i) {
    const float x = v[i];
    if (std::isnan(x)) {
      ++a.nan_count;
    } else if (std::isfinite(x)) {
      if (!a.min || x < *a.min) a.min = x;
      if (!a.max || x > *a.max) a.max = x;
    }
  }
}

namespace {

// A raw file without dimensions: say what is known (its size) and which cubes would fit.
FileInfo describe_headerless(const std::filesystem::path& path, const std::string& why) {
  FileInfo info{path.string(), "raw (no header)", {why}, {}};
  const uint64_t bytes = std::filesystem::file_size(path);
  std::string fits;
  const std::pair<uint64_t, const char*> types[] = {{1, "uint8"}, {2, "uint16/int16"}, {4, "float32"}, {8, "float64"}};
  for (auto [size, name] : types) {
    if (bytes % size) continue;
    const uint64_t n = bytes / size, edge = static_cast<uint64_t>(std::llround(std::cbrt(double(n))));
    if (edge * edge * edge == n) fits += (fits.empty() ? "" : ", ") + std::to_string(edge) + "^3 " + name;
  }
  info.notes.push_back(std::to_string(bytes) + " bytes" + (fits.empty() ? "" : "; cubes that fit: " + fits) +
                       " (pass --dims X,Y,Z --type T, or name it name_XxYxZ_type.raw)");
  return info;
}

}  // namespace

FileInfo describe_file(const std::filesystem::path& path, const VolumeOptions& options) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(path)) throw std::runtime_error(path.string() + ": is a directory");
  const std::string format = detect_volume_format(path);
  if (format == "netcdf") return describe_netcdf(path);
  if (format == "grib") return describe_grib(path);
  if (format == "vtk") return describe_vtk_legacy(path);
  if (format == "vti") return describe_vti(path);
  if (format == "nrrd") return describe_nrrd(path);
  if (format == "raw" || format == "dat") {
    // One array; a raw file says nothing about itself beyond what its name or .dat says.
    Volume v;
    try {
      v = format == "raw" ? read_raw_volume(path, options) : read_dat_volume(path, options);
    } catch (const std::runtime_error& e) {
      // Only a raw file that says nothing about itself is described rather than refused.
      const std::string m = e.what();
      if (format == "raw" && (m.find("without dimensions") != std::string::npos || m.find("without element type") != std::string::npos))
        return describe_headerless(path, "dimensions or element type unknown");
      throw;
    }
    FileInfo info{path.string(), format == "raw" ? "raw" : ".dat descriptor + raw data", {}, {}};
    ArrayInfo a;
    a.name = "(the only array)";
    a.kind = "volume";
    a.type = options.type != ScalarType::Unknown ? scalar_type_name(options.type) : "from the file name / descriptor";
    a.grid = v.dims;
    a.spacing = v.spacing;
    a.shape = std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" + std::to_string(v.dims[2]);
    accumulate_stats(a, v.values.data(), v.values.size());
    info.arrays.push_back(std::move(a));
    return info;
  }
  throw std::runtime_error(path.string() + ": unknown format (supported: .nc, .grib/.grib2, .vtk, .vti, .nrrd/.nhdr, .raw, .dat)");
}

std::string format_file_info(const FileInfo& info) {
  std::ostringstream os;
  os.precision(7);
  os << info.path << ": " << info.format << "\n";
  for (const auto& n : info.notes) os << "  " << n << "\n";
  for (const auto& a : info.arrays) {
    os << "  " << a.name << "  [" << a.kind << ", " << a.type;
    if (a.components > 1) os << ", " << a.components << " components";
    os << "] " << a.shape << "\n";
    if (a.grid[0] > 0) {
      os << "      grid " << a.grid[0] << "x" << a.grid[1] << "x" << a.grid[2] << " (x,y,z)";
      if (a.spacing != std::array<double, 3>{1, 1, 1})
        os << ", spacing " << a.spacing[0] << " " << a.spacing[1] << " " << a.spacing[2];
      os << "\n";
    } else {
      os << "      not loadable as a volume\n";
    }
    for (const auto& c : a.choices) os << "      " << c << "\n";
    if (a.values > 0) {
      os << "      range ";
      if (a.min) os << "[" << *a.min << ", " << *a.max << "]";
      else os << "(no finite values)";
      os << ", no data (NaN/fill/missing) " << a.nan_count << " of " << a.values << "\n";
    }
    for (const auto& n : a.notes) os << "      " << n << "\n";
  }
  return os.str();
}

nlohmann::json file_info_json(const FileInfo& info) {
  nlohmann::json j;
  j["path"] = info.path;
  j["format"] = info.format;
  j["notes"] = info.notes;
  j["arrays"] = nlohmann::json::array();
  for (const auto& a : info.arrays) {
    nlohmann::json x;
    x["name"] = a.name;
    x["kind"] = a.kind;
    x["type"] = a.type;
    x["shape"] = a.shape;
    x["grid"] = a.grid;
    x["spacing"] = a.spacing;
    x["components"] = a.components;
    x["choices"] = a.choices;
    x["notes"] = a.notes;
    x["values"] = a.values;
    x["nan_count"] = a.nan_count;
    if (a.min) x["range"] = {*a.min, *a.max};
    j["arrays"].push_back(x);
  }
  return j;
}

}  // namespace tfm
