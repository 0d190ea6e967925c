// NetCDF variables (netCDF-C: classic, 64-bit offset, CDF-5 and netCDF-4/HDF5) as volumes.
//
// Conventions (README "Formats"):
// - Dimension order. NetCDF stores C order, last dimension fastest, so x = the last dimension,
//   y = the one before, z = the one before that (e.g. U(time, lev, lat, lon): x = lon, y = lat,
//   z = lev). A variable with two such dimensions is one slice (z = 1).
// - The time dimension (the unlimited one, one named time/Time/t..., or one whose coordinate has
//   axis = "T", standard_name = "time" or units "... since ...") is never spatial: --time (or
//   ",time=N" in the spec) picks the index, default 0. Spatial dimensions come after it (CF order
//   T, Z, Y, X). Any other dimension (before time, or a fourth one: ensemble member,
//   ERA-Interim's "month", ...) is chosen with --member (",member=N"), default 0; at most one
//   such dimension may have more than one entry.
// - No data: values equal to _FillValue or any missing_value, outside valid_min/valid_max/
//   valid_range, or NaN become NaN; so do float/double values equal to netCDF's default fill
//   when no _FillValue is set. Fill values are compared with the stored (packed) values, so a NaN
//   _FillValue on an integer variable matches nothing (`tfmatch info` says so).
// - Packing: value = stored * scale_factor + add_offset (either may be absent; negative scales
//   are fine), in double precision, after honouring _Unsigned = "true".
// - Spacing: x and y take their coordinate variable's step when it is regular to within 1% of
//   the mean step (so Gaussian latitudes count as regular), else 1; z takes its coordinate's step
//   only when it is regular and has the same units as x (a Cartesian grid); pressure or model
//   levels give 1.
// - World orientation (grid_orientation.h): longitudes and latitudes increasing with x and y,
//   pressure and depth decreasing with z, heights increasing (CF "positive" counts); an axis
//   stored the other way is reversed, data and coordinates. Origin = first coordinate.
#include <netcdf.h>
#include <netcdf_mem.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/grid_orientation.h"
#include "tfmatch/io/netcdf4_probe.h"
#include "tfmatch/io/netcdf_classic.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"

namespace tfm {
namespace {

class NcFile {
 public:
  // A file on disk, or (`memory` not empty) its bytes in memory, named `name` in messages.
  NcFile(const std::filesystem::path& path, std::string_view memory = {}) : name_(path.string()) {
    if (memory.empty()) {
      std::error_code ec;
      size_ = std::filesystem::file_size(path, ec);
      if (ec) size_ = 0;
      std::ifstream in(path, std::ios::binary);
      check_netcdf_classic_header(
          [&](uint64_t offset, uint64_t n, char* out) {
            in.seekg(std::streamoff(offset));
            return bool(in.read(out, std::streamsize(n)));
          },
          size_, name_);
      std::string head(std::min<uint64_t>(size_, 4096), '\0');
      in.clear();
      in.seekg(0);
      in.read(head.data(), std::streamsize(head.size()));
      if (has_hdf5_signature(head)) probe_netcdf4_metadata(name_);
      check(nc_open(name_.c_str(), NC_NOWRITE, &id_), "cannot open as NetCDF");
    } else {
      check_netcdf_classic_header(
          [&](uint64_t offset, uint64_t n, char* out) {
            if (offset > memory.size() || n > memory.size() - offset) return false;
            std::memcpy(out, memory.data() + offset, n);
            return true;
          },
          memory.size(), name_);
      if (has_hdf5_signature(memory.substr(0, 4096))) probe_netcdf4_metadata(name_, memory);
      // netCDF-C does not write to memory opened without NC_WRITE.
      check(nc_open_mem(name_.c_str(), NC_NOWRITE, memory.size(), const_cast<char*>(memory.data()), &id_),
            "cannot open as NetCDF");
      size_ = memory.size();
    }
    // netCDF-C reads missing bytes of a truncated classic file as zeros: refuse such a file.
    int format = 0;
    if (nc_inq_format(id_, &format) == NC_NOERR && size_ > 0) {
      const uint64_t needed = netcdf_classic_minimum_size(id_, format);
      if (needed > size_) {
        nc_close(id_);
        id_ = -1;
        throw std::runtime_error(name_ + ": truncated: its header describes " +
                                 (needed == kNetcdfSizeOverflow ? "more than 2^62 bytes"
                                                                : "at least " + std::to_string(needed) + " bytes") +
                                 ", the file has " + std::to_string(size_));
      }
    }
  }
  ~NcFile() {
    if (id_ >= 0) nc_close(id_);
  }
  NcFile(const NcFile&) = delete;
  NcFile& operator=(const NcFile&) = delete;
  int id() const { return id_; }
  const std::string& name() const { return name_; }
  uint64_t size() const { return size_; }  // bytes of the file (0: unknown)
  void check(int status, const std::string& what) const {
    if (status != NC_NOERR) throw std::runtime_error(name_ + ": " + what + " (" + nc_strerror(status) + ")");
  }

 private:
  std::string name_;
  int id_ = -1;
  uint64_t size_ = 0;
};

bool is_numeric(nc_type t) {
  return t == NC_BYTE || t == NC_UBYTE || t == NC_SHORT || t == NC_USHORT || t == NC_INT || t == NC_UINT ||
         t == NC_INT64 || t == NC_UINT64 || t == NC_FLOAT || t == NC_DOUBLE;
}

const char* nc_type_name(nc_type t) {
  switch (t) {
    case NC_BYTE: return "int8";
    case NC_UBYTE: return "uint8";
    case NC_CHAR: return "char";
    case NC_SHORT: return "int16";
    case NC_USHORT: return "uint16";
    case NC_INT: return "int32";
    case NC_UINT: return "uint32";
    case NC_INT64: return "int64";
    case NC_UINT64: return "uint64";
    case NC_FLOAT: return "float32";
    case NC_DOUBLE: return "float64";
    case NC_STRING: return "string";
    default: return "user-defined";
  }
}

std::optional<std::string> att_text(int nc, int var, const char* name) {
  nc_type t;
  size_t len;
  if (nc_inq_att(nc, var, name, &t, &len) != NC_NOERR) return std::nullopt;
  // netCDF-4 may store text as one NC_STRING (as some Python writers do): the same text.
  if (t == NC_STRING && len == 1) {
    char* value = nullptr;
    if (nc_get_att_string(nc, var, name, &value) != NC_NOERR) return std::nullopt;
    std::string s = value ? std::string(value).substr(0, 4096) : std::string();
    nc_free_string(1, &value);
    return s;
  }
  if (t != NC_CHAR || len > 4096) return std::nullopt;
  std::string s(len, '\0');
  if (nc_get_att_text(nc, var, name, s.data()) != NC_NOERR) return std::nullopt;
  while (!s.empty() && s.back() == '\0') s.pop_back();
  return s;
}

std::optional<std::vector<double>> att_numbers(int nc, int var, const char* name) {
  nc_type t;
  size_t len;
  if (nc_inq_att(nc, var, name, &t, &len) != NC_NOERR || !is_numeric(t) || len == 0 || len > 64) return std::nullopt;
  std::vector<double> v(len);
  if (nc_get_att_double(nc, var, name, v.data()) != NC_NOERR) return std::nullopt;
  return v;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// The coordinate variable of a dimension: same name, one dimension, that dimension.
int coordinate_var(int nc, int dimid, const std::string& dim_name) {
  int v;
  int nd;
  int d;
  if (nc_inq_varid(nc, dim_name.c_str(), &v) != NC_NOERR) return -1;
  if (nc_inq_varndims(nc, v, &nd) != NC_NOERR || nd != 1) return -1;
  if (nc_inq_vardimid(nc, v, &d) != NC_NOERR || d != dimid) return -1;
  return v;
}

bool is_time_dimension(int nc, int dimid, const std::string& name) {
  int unlimited[NC_MAX_DIMS];
  int n = 0;
  if (nc_inq_unlimdims(nc, &n, unlimited) == NC_NOERR)
    for (int i = 0; i < n; ++i)
      if (unlimited[i] == dimid) return true;
  const std::string l = lower(name);
  if (l == "time" || l == "t" || l.rfind("time", 0) == 0) return true;
  const int cv = coordinate_var(nc, dimid, name);
  if (cv < 0) return false;
  auto axis = att_text(nc, cv, "axis");
  auto sn = att_text(nc, cv, "standard_name");
  auto units = att_text(nc, cv, "units");
  return (axis && (*axis == "T" || *axis == "t")) || (sn && *sn == "time") ||
         (units && lower(*units).find(" since ") != std::string::npos);
}

// How a variable's dimensions map to x, y, z, time and member.
struct Layout {
  int varid = -1;
  std::string name;
  nc_type type = NC_NAT;
  std::vector<int> dimids;
  std::vector<std::string> dim_names;
  std::vector<size_t> dim_sizes;
  int time_axis = -1;
  std::vector<int> extra_axes;          // leading non-time dimensions (members)
  std::array<int, 3> spatial{-1, -1, -1};  // file axis of x, y, z (-1: absent, size 1)
  int spatial_count = 0;
  bool is_coordinate = false;

  std::string shape() const {
    std::string s = "(";
    for (size_t i = 0; i < dim_names.size(); ++i) s += (i ? ", " : "") + dim_names[i] + "=" + std::to_string(dim_sizes[i]);
    return s + ")";
  }
  std::array<uint64_t, 3> grid() const {
    std::array<uint64_t, 3> g{1, 1, 1};
    for (int k = 0; k < 3; ++k)
      if (spatial[k] >= 0) g[k] = dim_sizes[spatial[k]];
    return g;
  }
};

// Dimensions that name ensemble members (lower case); never spatial.
bool is_member_dimension(const std::string& name, const std::string& member_dim) {
  if (!member_dim.empty()) return name == member_dim;
  std::string l = name;
  std::transform(l.begin(), l.end(), l.begin(), [](unsigned char c) { return std::tolower(c); });
  return l == "member" || l == "members" || l == "ensemble" || l == "realization" || l == "number";
}

Layout layout_of(const NcFile& f, int varid, const std::string& member_dim = "") {
  Layout L;
  L.varid = varid;
  char name[NC_MAX_NAME + 1];
  int nd = 0;
  f.check(nc_inq_var(f.id(), varid, name, &L.type, &nd, nullptr, nullptr), "cannot read variable metadata");
  L.name = name;
  L.dimids.resize(nd);
  f.check(nc_inq_vardimid(f.id(), varid, L.dimids.data()), "cannot read dimensions of " + L.name);
  std::vector<int> nontime;
  for (int i = 0; i < nd; ++i) {
    char dn[NC_MAX_NAME + 1];
    size_t len = 0;
    f.check(nc_inq_dim(f.id(), L.dimids[i], dn, &len), "cannot read a dimension of " + L.name);
    L.dim_names.push_back(dn);
    L.dim_sizes.push_back(len);
    if (L.time_axis < 0 && nd > 1 && is_time_dimension(f.id(), L.dimids[i], dn)) L.time_axis = i;
    else if (nd > 1 && is_member_dimension(dn, member_dim)) L.extra_axes.push_back(i);
    else nontime.push_back(i);
  }
  L.is_coordinate = nd == 1 && L.dim_names[0] == L.name;
  // x = last non-time dimension, y = the one before, z = the one before that; with a time
  // dimension only those after it (CF order T, Z, Y, X: what precedes T is a member axis).
  std::vector<int> candidates;
  for (int i : nontime)
    if (L.time_axis < 0 || i > L.time_axis || nontime.back() < L.time_axis) candidates.push_back(i);
  for (int k = 0; k < 3 && !candidates.empty(); ++k) {
    L.spatial[k] = candidates.back();
    candidates.pop_back();
    ++L.spatial_count;
  }
  for (int i : nontime)
    if (i != L.spatial[0] && i != L.spatial[1] && i != L.spatial[2]) L.extra_axes.push_back(i);
  std::sort(L.extra_axes.begin(), L.extra_axes.end());
  return L;
}

// Turns stored values into physical values with NaN for no data.
struct Unpacker {
  std::vector<double> missing;
  std::optional<double> valid_min, valid_max;
  bool valid_unpacked = false;  // valid_* given in the unpacked type
  bool unsigned_fix = false;
  int bits = 0;
  double scale = 1.0, offset = 0.0;
  std::optional<double> default_fill;
  std::vector<std::string> notes;

  float operator()(double raw) const {
    if (std::isnan(raw)) return NAN;
    for (double m : missing)
      if (raw == m) return NAN;
    if (default_fill && raw == *default_fill) return NAN;
    if (unsigned_fix && raw < 0) raw += std::ldexp(1.0, bits);
    const double v = raw * scale + offset;
    const double check = valid_unpacked ? v : raw;
    if ((valid_min && check < *valid_min) || (valid_max && check > *valid_max)) return NAN;
    return static_cast<float>(v);
  }
};

// A packing attribute (scale_factor, add_offset): absent, or one finite number. Anything else
// changes what every value means, so it is an error naming it rather than a default taken in
// silence (a text scale_factor "abc" left the data unscaled).
std::optional<double> packing_attribute(const NcFile& f, const Layout& L, const char* key) {
  nc_type t;
  size_t len = 0;
  if (nc_inq_att(f.id(), L.varid, key, &t, &len) != NC_NOERR) return std::nullopt;
  const std::string where = f.name() + ": variable " + L.name + ": attribute " + key;
  if (!is_numeric(t)) throw std::runtime_error(where + " is text, not a number");
  if (len != 1) throw std::runtime_error(where + " has " + std::to_string(len) + " values, not one");
  double v = 0;
  if (nc_get_att_double(f.id(), L.varid, key, &v) != NC_NOERR || !std::isfinite(v))
    throw std::runtime_error(where + " is not a finite number");
  return v;
}

Unpacker unpacker_of(const NcFile& f, const Layout& L) {
  Unpacker u;
  const int nc = f.id(), v = L.varid;
  const bool integer = L.type != NC_FLOAT && L.type != NC_DOUBLE;
  auto fill = att_numbers(nc, v, "_FillValue");
  if (fill) {
    u.missing.push_back((*fill)[0]);
    std::ostringstream os;
    os << "_FillValue " << (*fill)[0];
    if (std::isnan((*fill)[0]) && integer) os << " on an integer variable: matches no stored value, ignored";
    u.notes.push_back(os.str());
  } else if (L.type == NC_FLOAT) {
    u.default_fill = double(NC_FILL_FLOAT);
  } else if (L.type == NC_DOUBLE) {
    u.default_fill = NC_FILL_DOUBLE;
  }
  if (auto mv = att_numbers(nc, v, "missing_value")) {
    u.missing.insert(u.missing.end(), mv->begin(), mv->end());
    std::ostringstream os;  // as _FillValue is printed: 1e+20, not std::to_string's 100000000000000000000.000000
    os << "missing_value " << (*mv)[0] << (mv->size() > 1 ? " ..." : "");
    u.notes.push_back(os.str());
  }
  const auto sf = packing_attribute(f, L, "scale_factor");
  const auto ao = packing_attribute(f, L, "add_offset");
  if (sf) u.scale = *sf;
  if (ao) u.offset = *ao;
  if (sf || ao) {
    std::ostringstream os;
    os.precision(15);
    os << "packed: value = stored * " << u.scale << " + " << u.offset;
    u.notes.push_back(os.str());
  }
  const auto un = att_text(nc, v, "_Unsigned");
  nc_type ut;
  size_t ulen;
  if ((un && lower(*un) != "true" && lower(*un) != "false") ||
      (!un && nc_inq_att(nc, v, "_Unsigned", &ut, &ulen) == NC_NOERR))
    throw std::runtime_error(f.name() + ": variable " + L.name + ": attribute _Unsigned is " +
                             (un ? "'" + *un + "'" : std::string("not text")) + ", not \"true\" or \"false\"");
  if (un && lower(*un) == "true" && (L.type == NC_BYTE || L.type == NC_SHORT || L.type == NC_INT)) {
    u.unsigned_fix = true;
    u.bits = L.type == NC_BYTE ? 8 : L.type == NC_SHORT ? 16 : 32;
    u.notes.push_back("_Unsigned = true");
  }
  // valid_* in the variable's own type are stored values; in another type (the packed case),
  // unpacked values (NetCDF User Guide).
  nc_type at;
  size_t alen;
  for (const char* key : {"valid_range", "valid_min", "valid_max"}) {
    auto vals = att_numbers(nc, v, key);
    if (!vals) continue;
    if (nc_inq_att(nc, v, key, &at, &alen) == NC_NOERR && at != L.type && (sf || ao)) u.valid_unpacked = true;
    if (std::strcmp(key, "valid_range") == 0 && vals->size() >= 2) u.valid_min = (*vals)[0], u.valid_max = (*vals)[1];
    if (std::strcmp(key, "valid_min") == 0) u.valid_min = (*vals)[0];
    if (std::strcmp(key, "valid_max") == 0) u.valid_max = (*vals)[0];
    u.notes.push_back(std::string(key) + " applied");
  }
  return u;
}

std::string units_family(const std::optional<std::string>& u) {
  if (!u) return "";
  std::string l = lower(*u);
  return l.rfind("degree", 0) == 0 ? "degree" : l;
}

// Step of a dimension's coordinate when regular within 1% of the mean step, with its units.
std::pair<std::optional<double>, std::string> regular_step(const NcFile& f, const Layout& L, int axis) {
  const int cv = coordinate_var(f.id(), L.dimids[axis], L.dim_names[axis]);
  const size_t n = L.dim_sizes[axis];
  if (cv < 0 || n < 2 || n > (size_t(1) << 24)) return {std::nullopt, ""};
  nc_type t;
  if (nc_inq_vartype(f.id(), cv, &t) != NC_NOERR || !is_numeric(t)) return {std::nullopt, ""};
  std::vector<double> c(n);
  if (nc_get_var_double(f.id(), cv, c.data()) != NC_NOERR) return {std::nullopt, ""};
  const double mean = (c.back() - c.front()) / double(n - 1);
  if (!std::isfinite(mean) || mean == 0) return {std::nullopt, ""};
  for (size_t i = 1; i < n; ++i)
    if (!(std::abs((c[i] - c[i - 1]) - mean) <= 0.01 * std::abs(mean))) return {std::nullopt, ""};
  return {std::abs(mean), units_family(att_text(f.id(), cv, "units"))};
}

std::array<double, 3> spacing_of(const NcFile& f, const Layout& L) {
  std::array<double, 3> s{1, 1, 1};
  std::string x_units;
  bool x_regular = false;
  for (int k = 0; k < 3; ++k) {
    if (L.spatial[k] < 0) continue;
    auto [step, u] = regular_step(f, L, L.spatial[k]);
    if (!step) continue;
    if (k == 0) x_regular = true, x_units = u;
    // Horizontal steps always; a vertical step only in the units of x (else it would mix, say,
    // hPa with degrees).
    if (k < 2 || (x_regular && !u.empty() && u == x_units)) s[k] = *step;
  }
  return s;
}

// Candidate data variables: numeric, not coordinates, at least two spatial dimensions.
std::vector<std::string> volume_variables(const NcFile& f) {
  int nvars = 0;
  f.check(nc_inq_nvars(f.id(), &nvars), "cannot list variables");
  std::vector<std::string> out;
  for (int v = 0; v < nvars; ++v) {
    Layout L = layout_of(f, v);
    if (is_numeric(L.type) && !L.is_coordinate && L.spatial_count >= 2) out.push_back(L.name);
  }
  return out;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

size_t pick_index(const Layout& L, int axis, std::optional<uint64_t> requested, const char* flag, const std::string& file) {
  if (axis < 0) {
    if (requested && *requested > 0)
      throw std::runtime_error(file + ": variable " + L.name + " has no " + (std::strcmp(flag, "time") == 0 ? "time" : "member") +
                               " dimension (" + flag + " " + std::to_string(*requested) + " given)");
    return 0;
  }
  const uint64_t i = requested.value_or(0);
  if (i >= L.dim_sizes[axis])
    throw std::runtime_error(file + ": variable " + L.name + ": " + flag + " " + std::to_string(i) + " is out of range (dimension " +
                             L.dim_names[axis] + " has " + std::to_string(L.dim_sizes[axis]) + ")");
  return static_cast<size_t>(i);
}

// Values read per call at most (12 bytes each: as double, then unpacked to float), unless one row
// of the fastest spatial axis is longer.
constexpr uint64_t kSlabReadValues = uint64_t(1) << 20;

// Calls fn(values, n) for each 2D (or 1D) slab of the variable at the given leading indices, in
// order, a block of rows of the slab at a time (an 8192 x 8192 slab took 768 MiB read whole);
// `iterate` holds the axes that are not one of the last two spatial axes, slowest first.
template <class Fn>
void for_each_slab(const NcFile& f, const Layout& L, std::vector<size_t> start, const std::vector<int>& iterate, Fn fn) {
  const size_t nd = L.dim_sizes.size();
  std::vector<size_t> count(nd, 1);
  for (int k = 0; k < 2; ++k)
    if (L.spatial[k] >= 0) count[L.spatial[k]] = L.dim_sizes[L.spatial[k]];
  // The slab's slower spatial axis is read a block of rows at a time: each block is the next
  // values of the slab in its order.
  const int rows_axis = L.spatial[0] >= 0 && L.spatial[1] >= 0 ? std::min(L.spatial[0], L.spatial[1]) : -1;
  const size_t rows = rows_axis >= 0 ? L.dim_sizes[rows_axis] : 1;
  size_t row = 1;
  for (size_t a = 0; a < nd; ++a)
    if (int(a) != rows_axis) row *= count[a];
  const size_t block_rows = rows_axis >= 0 ? std::clamp<size_t>(kSlabReadValues / std::max<size_t>(row, 1), 1, rows) : 1;
  const size_t block = row * block_rows;
  check_memory(uint64_t(block) * (sizeof(double) + sizeof(float)), f.name() + ": reading variable " + L.name + " " + L.shape());
  std::vector<double> buf(block);
  const Unpacker u = unpacker_of(f, L);
  std::vector<float> out(block);
  while (true) {
    for (size_t r0 = 0; r0 < rows; r0 += block_rows) {
      checkpoint("load");
      if (rows_axis >= 0) {
        start[rows_axis] = r0;
        count[rows_axis] = std::min(block_rows, rows - r0);
      }
      const size_t n = row * (rows_axis >= 0 ? count[rows_axis] : 1);
      f.check(nc_get_vara_double(f.id(), L.varid, start.data(), count.data(), buf.data()), "cannot read variable " + L.name);
      for (size_t i = 0; i < n; ++i) out[i] = u(buf[i]);
      fn(out.data(), n);
    }
    if (rows_axis >= 0) start[rows_axis] = 0;
    // Odometer over the axes to iterate (last one fastest).
    int k = static_cast<int>(iterate.size()) - 1;
    for (; k >= 0; --k) {
      if (++start[iterate[k]] < L.dim_sizes[iterate[k]]) break;
      start[iterate[k]] = 0;
    }
    if (k < 0) return;
  }
}

// The variable `options` select, its layout and its member axis (-1: none).
struct Selection {
  Layout layout;
  int member_axis = -1;
};

Selection select_variable(const NcFile& f, const VolumeOptions& options) {
  const std::string& file = f.name();
  std::string var = options.variable;
  if (var.empty()) {
    auto candidates = volume_variables(f);
    if (candidates.size() != 1)
      throw std::runtime_error(file + ": choose a variable (file.nc:VAR or " + parameter("var") + "): " +
                               (candidates.empty() ? std::string("no variable has two or more spatial dimensions")
                                                   : "candidates are " + join(candidates)));
    var = candidates.front();
  }
  int varid;
  if (nc_inq_varid(f.id(), var.c_str(), &varid) != NC_NOERR)
    throw std::runtime_error(file + ": no variable '" + var + "' (volume variables: " + join(volume_variables(f)) + ")");
  Selection sel{layout_of(f, varid, options.member_dim), -1};
  const Layout& L = sel.layout;
  if (!is_numeric(L.type))
    throw std::runtime_error(file + ": variable " + var + " has type " + nc_type_name(L.type) + ", not a numeric type");
  if (L.spatial_count == 0) throw std::runtime_error(file + ": variable " + var + " is a scalar");
  if (!options.member_dim.empty()) {
    auto it = std::find(L.dim_names.begin(), L.dim_names.end(), options.member_dim);
    if (it == L.dim_names.end())
      throw std::runtime_error(file + ": variable " + var + " has no dimension '" + options.member_dim + "' (" + parameter("member-dim") + "); its shape is " +
                               L.shape());
    sel.member_axis = int(it - L.dim_names.begin());
  }
  for (int a : L.extra_axes) {
    if (L.dim_sizes[a] <= 1 || a == sel.member_axis) continue;
    if (sel.member_axis >= 0)
      throw std::runtime_error(file + ": variable " + var + " has two leading dimensions besides time (" +
                               L.dim_names[sel.member_axis] + ", " + L.dim_names[a] +
                               "); only one can be chosen with " + parameter("member") + " (name it with " +
                               parameter("member-dim") + ")");
    sel.member_axis = a;
  }
  return sel;
}

// Name, units and values of the coordinate variable of a spatial axis (nothing when it has none).
GridAxis grid_axis(const NcFile& f, const Layout& L, int axis) {
  GridAxis g;
  g.name = L.dim_names[axis];
  const int cv = coordinate_var(f.id(), L.dimids[axis], L.dim_names[axis]);
  nc_type t;
  if (cv < 0 || nc_inq_vartype(f.id(), cv, &t) != NC_NOERR || !is_numeric(t)) return g;
  g.units = att_text(f.id(), cv, "units").value_or("");
  std::vector<double> c(L.dim_sizes[axis]);
  if (nc_get_var_double(f.id(), cv, c.data()) != NC_NOERR) return g;
  if (std::all_of(c.begin(), c.end(), [](double x) { return std::isfinite(x); })) g.coordinates = std::move(c);
  return g;
}

// The spatial axes' names, units and coordinates, and which to reverse for world orientation.
std::pair<std::array<GridAxis, 3>, WorldOrientation> oriented_axes(const NcFile& f, const Layout& L) {
  std::array<GridAxis, 3> axes;
  std::array<std::string, 3> positive;
  for (int k = 0; k < 3; ++k) {
    if (L.spatial[k] < 0) continue;
    axes[k] = grid_axis(f, L, L.spatial[k]);
    const int cv = coordinate_var(f.id(), L.dimids[L.spatial[k]], L.dim_names[L.spatial[k]]);
    if (cv >= 0) positive[k] = att_text(f.id(), cv, "positive").value_or("");
  }
  return {axes, world_orientation(axes, L.grid(), positive)};
}

Volume read_netcdf(const NcFile& f, const VolumeOptions& options) {
  const std::string& file = f.name();
  const Selection sel = select_variable(f, options);
  const Layout& L = sel.layout;
  const std::string& var = L.name;
  const int member_axis = sel.member_axis;
  std::vector<size_t> start(L.dim_sizes.size(), 0);
  const size_t t = pick_index(L, L.time_axis, options.time_index, "time", file);
  const size_t m = pick_index(L, member_axis, options.member_index, "member", file);
  if (L.time_axis >= 0) start[L.time_axis] = t;
  if (member_axis >= 0) start[member_axis] = m;

  Volume v;
  v.dims = L.grid();
  const uint64_t voxels = checked_voxel_count(v.dims, file);
  int format = 0;
  f.check(nc_inq_format(f.id(), &format), "cannot read the format");
  // A classic file stores every value, so a slab cannot exceed the file (checked before
  // allocating); compressed netCDF-4 has no such bound, so cap it at 2^34 voxels (64 GiB).
  if ((format == NC_FORMAT_NETCDF4 || format == NC_FORMAT_NETCDF4_CLASSIC) ? voxels > (uint64_t(1) << 34)
                                                                           : (f.size() > 0 && voxels > f.size()))
    throw std::runtime_error(file + ": variable " + var + " is larger than the file can hold (" + L.shape() + ")");
  v.spacing = spacing_of(f, L);
  const auto [axes, orientation] = oriented_axes(f, L);
  v.axes = axes;
  v.name = file + ":" + var;
  v.units = att_text(f.id(), L.varid, "units").value_or("");
  if (L.time_axis >= 0 && L.dim_sizes[L.time_axis] > 1) v.name += ",time=" + std::to_string(t);
  if (member_axis >= 0) v.name += ",member=" + std::to_string(m);
  check_memory(voxels * sizeof(float), file + ": variable " + var + " " + L.shape());
  v.values.reserve(voxels);
  std::vector<int> iterate;
  if (L.spatial[2] >= 0) iterate.push_back(L.spatial[2]);
  for_each_slab(f, L, start, iterate, [&](const float* s, size_t n) { v.values.insert(v.values.end(), s, s + n); });
  apply_world_orientation(v, orientation);
  return v;
}

// A NetCDF variable read slab by slab: one nc_get_vara per z-slice (the file's slice under world
// orientation), unpacked and flipped as read_netcdf() does for the whole volume.
class NetcdfSlabs final : public VolumeSlabReader {
 public:
  NetcdfSlabs(const std::filesystem::path& path, const VolumeOptions& options) : file_(path) {
    const std::string& file = file_.name();
    const Selection sel = select_variable(file_, options);
    layout_ = sel.layout;
    start_.assign(layout_.dim_sizes.size(), 0);
    const size_t t = pick_index(layout_, layout_.time_axis, options.time_index, "time", file);
    const size_t m = pick_index(layout_, sel.member_axis, options.member_index, "member", file);
    if (layout_.time_axis >= 0) start_[layout_.time_axis] = t;
    if (sel.member_axis >= 0) start_[sel.member_axis] = m;
    grid_.dims = layout_.grid();
    const uint64_t voxels = checked_voxel_count(grid_.dims, file);
    int format = 0;
    file_.check(nc_inq_format(file_.id(), &format), "cannot read the format");
    if (format != NC_FORMAT_NETCDF4 && format != NC_FORMAT_NETCDF4_CLASSIC && file_.size() > 0 && voxels > file_.size())
      throw std::runtime_error(file + ": variable " + layout_.name + " is larger than the file can hold (" +
                               layout_.shape() + ")");
    grid_.spacing = spacing_of(file_, layout_);
    const auto [axes, orientation] = oriented_axes(file_, layout_);
    grid_.axes = axes;
    orientation_ = orientation;
    orient_axes(grid_.axes, grid_.origin, grid_.spacing, orientation_);
    grid_.name = file + ":" + layout_.name;
    grid_.units = att_text(file_.id(), layout_.varid, "units").value_or("");
    if (layout_.time_axis >= 0 && layout_.dim_sizes[layout_.time_axis] > 1) grid_.name += ",time=" + std::to_string(t);
    if (sel.member_axis >= 0) grid_.name += ",member=" + std::to_string(m);
    unpack_ = unpacker_of(file_, layout_);
  }

  void read_slices(uint64_t z0, uint64_t nz, float* out) override {
    check_slices(z0, nz);
    const uint64_t nx = grid_.dims[0], ny = grid_.dims[1], s = slice_voxels();
    std::vector<size_t> start = start_, count(start_.size(), 1);
    for (int k = 0; k < 2; ++k)
      if (layout_.spatial[k] >= 0) count[layout_.spatial[k]] = layout_.dim_sizes[layout_.spatial[k]];
    check_memory(s * sizeof(double), file_.name() + ": reading a slice of " + layout_.name + " " + layout_.shape());
    buffer_.resize(s);
    for (uint64_t z = z0; z < z0 + nz; ++z) {
      checkpoint("load");
      if (layout_.spatial[2] >= 0) start[layout_.spatial[2]] = orientation_.flip[2] ? grid_.dims[2] - 1 - z : z;
      file_.check(nc_get_vara_double(file_.id(), layout_.varid, start.data(), count.data(), buffer_.data()),
                  "cannot read variable " + layout_.name);
      float* slice = out + (z - z0) * s;
      for (uint64_t y = 0; y < ny; ++y)
        for (uint64_t x = 0; x < nx; ++x) {
          const uint64_t sx = orientation_.flip[0] ? nx - 1 - x : x, sy = orientation_.flip[1] ? ny - 1 - y : y;
          slice[y * nx + x] = unpack_(buffer_[sy * nx + sx]);
        }
    }
  }

 private:
  NcFile file_;
  Layout layout_;
  std::vector<size_t> start_;
  WorldOrientation orientation_;
  Unpacker unpack_;
  std::vector<double> buffer_;
};

// The most values `info` reads of one variable for its range: 16 GiB of float data, tens of
// seconds from a fast disk. A netCDF-4 file of a few KiB can declare an unwritten 10 x 10^5 x 10^5
// variable, which would otherwise stream 10^11 fill values for a quarter of an hour.
constexpr uint64_t kInfoMaxValues = uint64_t(1) << 32;

FileInfo describe_netcdf(const NcFile& f, const VolumeOptions& options) {
  FileInfo info;
  info.path = f.name();
  int format = 0;
  f.check(nc_inq_format(f.id(), &format), "cannot read the format");
  info.format = format == NC_FORMAT_CLASSIC         ? "NetCDF classic"
                : format == NC_FORMAT_64BIT_OFFSET  ? "NetCDF 64-bit offset"
                : format == NC_FORMAT_CDF5          ? "NetCDF CDF-5"
                : format == NC_FORMAT_NETCDF4       ? "NetCDF-4 (HDF5)"
                                                    : "NetCDF-4 classic model (HDF5)";
  if (auto title = att_text(f.id(), NC_GLOBAL, "title")) info.notes.push_back("title: " + *title);
  int ngroups = 0;
  if (nc_inq_grps(f.id(), &ngroups, nullptr) == NC_NOERR && ngroups > 0)
    info.notes.push_back(std::to_string(ngroups) + " groups: only variables of the root group are read");
  int nvars = 0;
  f.check(nc_inq_nvars(f.id(), &nvars), "cannot list variables");
  for (int v = 0; v < nvars; ++v) {
    Layout L = layout_of(f, v, options.member_dim);
    ArrayInfo a;
    a.name = L.name;
    a.kind = L.is_coordinate ? "coordinate" : "variable";
    a.type = nc_type_name(L.type);
    a.shape = L.shape();
    if (auto ln = att_text(f.id(), v, "long_name")) a.notes.push_back(*ln);
    if (auto un = att_text(f.id(), v, "units")) a.notes.push_back("units: " + *un);
    if (!is_numeric(L.type) || L.spatial_count == 0) {
      a.notes.push_back("not numeric or scalar: not a volume");
      info.arrays.push_back(std::move(a));
      continue;
    }
    a.grid = L.grid();
    a.spacing = spacing_of(f, L);
    auto [axes, orientation] = oriented_axes(f, L);  // as loaded: reversed axes and their origin
    orient_axes(axes, a.origin, a.spacing, orientation);
    a.orientation = orientation_lines(axes, a.origin, a.spacing, orientation);
    if (L.time_axis >= 0)
      a.choices.push_back("time: " + L.dim_names[L.time_axis] + " = " + std::to_string(L.dim_sizes[L.time_axis]) + " (" + parameter("time") + ")");
    for (int e : L.extra_axes)
      a.choices.push_back("member: " + L.dim_names[e] + " = " + std::to_string(L.dim_sizes[e]) + " (" + parameter("member") + ")");
    // A variable whose packing cannot be read is listed saying why, not the end of the listing.
    Unpacker u;
    try {
      u = unpacker_of(f, L);
    } catch (const std::runtime_error& e) {
      const std::string m = e.what();
      a.notes.push_back("not loadable: " + m.substr(std::min(m.size(), f.name().size() + 2)));
      info.arrays.push_back(std::move(a));
      continue;
    }
    a.notes.insert(a.notes.end(), u.notes.begin(), u.notes.end());
    // Every slab of every time and member counts towards the range.
    std::vector<int> iterate;
    for (size_t i = 0; i < L.dim_sizes.size(); ++i)
      if (int(i) != L.spatial[0] && int(i) != L.spatial[1]) iterate.push_back(int(i));
    bool empty = false;
    uint64_t values = 1;
    for (size_t s : L.dim_sizes) {
      empty |= s == 0;
      values = values > kInfoMaxValues ? values : values * s;
    }
    if (!empty && values > kInfoMaxValues) {
      a.notes.push_back("range not computed: " + std::to_string(values) +
                        " values, more than info reads of one variable (2^32)");
      info.arrays.push_back(std::move(a));
      continue;
    }
    // A variable whose rows do not fit the memory budget is described without its range, not the
    // end of the whole listing.
    if (!empty) try {
        for_each_slab(f, L, std::vector<size_t>(L.dim_sizes.size(), 0), iterate,
                      [&](const float* s, size_t n) { accumulate_stats(a, s, n); });
      } catch (const MemoryBudgetExceeded& e) {
        a.values = a.nan_count = 0;
        a.min = a.max = std::nullopt;
        a.notes.push_back(std::string("range not computed: ") + e.what());
      }
    info.arrays.push_back(std::move(a));
  }
  return info;
}

}  // namespace

uint64_t count_netcdf_members(const std::filesystem::path& path, const VolumeOptions& options) {
  NcFile f(path);
  const Selection sel = select_variable(f, options);
  return sel.member_axis >= 0 ? sel.layout.dim_sizes[sel.member_axis] : 1;
}

Volume read_netcdf_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  return read_netcdf(NcFile(path), options);
}

FileInfo describe_netcdf(const std::filesystem::path& path, const VolumeOptions& options) {
  return describe_netcdf(NcFile(path), options);
}

std::unique_ptr<VolumeSlabReader> open_netcdf_slabs(const std::filesystem::path& path, const VolumeOptions& options) {
  // netCDF-C reads any hyperslab, of compressed netCDF-4 too (a chunk at a time, cached).
  return std::make_unique<NetcdfSlabs>(path, options);
}

Volume parse_netcdf(std::string_view bytes, const std::string& name, const VolumeOptions& options) {
  if (bytes.empty()) throw std::runtime_error(name + ": empty file");
  return read_netcdf(NcFile(name, bytes), options);
}

FileInfo describe_netcdf_bytes(std::string_view bytes, const std::string& name) {
  if (bytes.empty()) throw std::runtime_error(name + ": empty file");
  return describe_netcdf(NcFile(name, bytes), {});
}

}  // namespace tfm
