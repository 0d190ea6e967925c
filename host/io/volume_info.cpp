// describe_file(): the describer of the file's row of the format table; text and JSON renderings of
// the result.
#include "tfmatch/io/volume_info.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_formats.h"

namespace tfm {

void accumulate_stats(ArrayInfo& a, const float* v, uint64_t n) {
  a.values += n;
  for (uint64_t i = 0; i < n; ++i) {
    const float x = v[i];
    if (!std::isfinite(x)) {
      ++a.nan_count;  // no data: NaN and ±Inf (DESIGN.md)
    } else {
      if (!a.min || x < *a.min) a.min = x;
      if (!a.max || x > *a.max) a.max = x;
    }
  }
}

FileInfo describe_file(const std::filesystem::path& path, const VolumeOptions& options) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(path)) throw std::runtime_error(path.string() + ": is a directory");
  const VolumeFormat* format = find_volume_format(path);
  if (!format) throw std::runtime_error(unknown_volume_format_message(path));
  return format->describe(path, options);
}

FileInfo describe_selection(const std::string& spec, const VolumeOptions& options) {
  const VolumeSpec parsed = parse_volume_spec(spec, options);
  const VolumeFormat* format = find_volume_format(parsed.path);
  const Volume v = load_volume(spec, options);
  FileInfo info;
  info.path = parsed.path.string();
  info.format = format ? format->title : "";
  ArrayInfo a;
  a.name = v.name;
  a.kind = "selection";
  a.type = "float32 as loaded";
  a.shape = "(x=" + std::to_string(v.dims[0]) + ", y=" + std::to_string(v.dims[1]) + ", z=" + std::to_string(v.dims[2]) + ")";
  a.grid = v.dims;
  a.spacing = v.spacing;
  a.origin = v.origin;
  const VolumeOptions& o = parsed.options;
  if (!o.variable.empty()) a.choices.push_back("variable " + o.variable);
  if (o.time_index) a.choices.push_back("time index " + std::to_string(*o.time_index));
  if (o.member_index) a.choices.push_back("member index " + std::to_string(*o.member_index));
  static const char* const axis_names[3] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    const GridAxis& ax = v.axes[size_t(i)];
    if (ax.name.empty() && ax.coordinates.empty()) continue;
    std::ostringstream line;
    line.precision(7);
    line << axis_names[i] << ": " << (ax.name.empty() ? "coordinates" : ax.name) << " " << axis_coordinate(v, i, 0)
         << " .. " << axis_coordinate(v, i, v.dims[size_t(i)] - 1) << (ax.units.empty() ? "" : " " + ax.units);
    a.orientation.push_back(line.str());
  }
  if (!v.units.empty()) a.notes.push_back("units: " + v.units);  // as describe() says it
  accumulate_stats(a, v.values.data(), v.values.size());
  info.arrays.push_back(std::move(a));
  return info;
}

namespace {

// How many fields (times, members) an array's range and no-data count cover: its values over one
// field's (1 where the grid is unknown).
uint64_t fields_examined(const ArrayInfo& a) {
  const uint64_t per_field = a.grid[0] * a.grid[1] * a.grid[2] * std::max<uint64_t>(a.components, 1);
  return per_field > 0 && a.values > per_field ? a.values / per_field : 1;
}

// " over all 4 times" where the range covers more than one field: a range copied into --range
// from here maps the field of one time differently than that field's own range would.
std::string range_scope(const ArrayInfo& a) {
  const uint64_t fields = fields_examined(a);
  if (fields <= 1) return "";
  bool times = false, members = false;
  for (const std::string& c : a.choices) {
    times = times || c.find("(--time)") != std::string::npos;
    members = members || c.find("(--member)") != std::string::npos;
  }
  const char* what = times && members ? "times and members" : times ? "times" : members ? "members" : "fields";
  return " over all " + std::to_string(fields) + " " + what;
}

}  // namespace

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
      if (a.origin != std::array<double, 3>{0, 0, 0})
        os << ", origin " << a.origin[0] << " " << a.origin[1] << " " << a.origin[2];
      os << "\n";
      for (const auto& line : a.orientation) os << "      " << line << "\n";
    } else {
      os << "      not loadable as a volume\n";
    }
    for (const auto& c : a.choices) os << "      " << c << "\n";
    if (a.values > 0) {
      os << "      range" << range_scope(a) << " ";
      if (a.min) os << "[" << *a.min << ", " << *a.max << "]";
      else os << "(no finite values)";
      os << ", no data (NaN/Inf/fill/missing) " << a.nan_count << " of " << a.values << "\n";
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
    x["origin"] = a.origin;
    if (!a.orientation.empty()) x["orientation"] = a.orientation;
    x["components"] = a.components;
    x["choices"] = a.choices;
    x["notes"] = a.notes;
    x["values"] = a.values;
    x["nan_count"] = a.nan_count;
    x["fields_examined"] = fields_examined(a);  // times and members the range and count cover
    if (a.min) x["range"] = {*a.min, *a.max};
    j["arrays"].push_back(x);
  }
  return j;
}

}  // namespace tfm
