// GRIB 1 and 2 (ecCodes) as volumes: the messages of one parameter (shortName) on one level type,
// stacked by level into z.
//
// Conventions (README "Formats"):
// - Selection: "file.grib2:SHORTNAME" or "file.grib2:SHORTNAME@TYPEOFLEVEL". Without a level type
//   the one with the most distinct levels is taken (isobaricInhPa for GFS u, v, t, ...).
// - z: the selected messages sorted by level value, two messages at one level being an error.
// - x, y: the message's grid points in its scanning order (x = i along a row, y = rows), as
//   ecCodes returns them; for most global grids row 0 is the northernmost.
// - World orientation (grid_orientation.h), applied last: latitudes increasing with y,
//   longitudes with x, pressure (and hybrid model levels) decreasing with z so the surface is
//   at z = 0, heights increasing, depths decreasing; data and coordinates reversed together.
// - --time picks among the distinct (reference date and time, forecast step) pairs, sorted
//   (analysis times of a reanalysis, forecast steps of a run); --member among the distinct
//   ensemble numbers ("number"), sorted. Both default to the first.
// - Missing values (bitmap) become NaN. Messages on different grids are an error.
// - Spacing: regular lat/lon or Gaussian grids take their increments in degrees (Gaussian
//   latitudes: the mean step), projected grids their Dx/Dy in metres; z spacing is 1.
#include <eccodes.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "tfmatch/io/grid_orientation.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"

namespace tfm {
namespace {

// Marks missing points: no packing of physical data produces this value.
constexpr double kMissing = 1.0e30;

struct HandleDeleter {
  void operator()(codes_handle* h) const { codes_handle_delete(h); }
};
using Handle = std::unique_ptr<codes_handle, HandleDeleter>;

std::optional<std::string> get_string(codes_handle* h, const char* key) {
  char buf[256];
  size_t len = sizeof(buf);
  if (codes_get_string(h, key, buf, &len) != CODES_SUCCESS) return std::nullopt;
  return std::string(buf);
}
std::optional<long> get_long(codes_handle* h, const char* key) {
  long v = 0;
  int err = 0;
  if (codes_is_missing(h, key, &err) == 1 || err != 0) return std::nullopt;
  if (codes_get_long(h, key, &v) != CODES_SUCCESS) return std::nullopt;
  return v;
}
std::optional<double> get_double(codes_handle* h, const char* key) {
  double v = 0;
  int err = 0;
  if (codes_is_missing(h, key, &err) == 1 || err != 0) return std::nullopt;
  if (codes_get_double(h, key, &v) != CODES_SUCCESS) return std::nullopt;
  return v;
}

// GRIB2 stores a fixed surface's scaled value in sign-and-magnitude (the top bit the sign, as -2
// PVU is 0x800007D0); ecCodes' level keys read it unsigned (2147486 for -2 PVU). `level` as
// ecCodes gives it, negated and rescaled to the magnitude when the sign bit of `scaled_key` is set.
double signed_level(codes_handle* h, double level, const char* scaled_key) {
  constexpr long kSign = long(1) << 31;
  const std::optional<long> scaled = get_long(h, scaled_key);
  if (!scaled || *scaled < kSign || *scaled >= 2 * kSign - 1) return level;  // no key, positive, or missing
  if (*scaled == kSign) return 0.0;  // minus zero
  return -level * double(*scaled - kSign) / double(*scaled);
}

struct Message {
  Handle handle;
  int index = 0;  // 1-based position in the file
  std::string short_name, level_type, grid_type;
  double level = 0, bottom = 0;
  std::tuple<long, long, long, long> time{0, 0, 0, 0};  // dataDate, dataTime, startStep, endStep
  long member = 0;
  long ni = 0, nj = 0;
  std::array<double, 4> corners{0, 0, 0, 0};  // lat/lon of first and last grid points

  std::string grid_text() const {
    std::ostringstream os;
    os << grid_type << " " << ni << "x" << nj << " from (" << corners[0] << ", " << corners[1] << ") to (" << corners[2]
       << ", " << corners[3] << ")";
    return os.str();
  }
  bool same_grid(const Message& o) const {
    if (grid_type != o.grid_type || ni != o.ni || nj != o.nj) return false;
    for (int i = 0; i < 4; ++i)
      if (std::abs(corners[i] - o.corners[i]) > 1e-6) return false;
    return true;
  }
};

std::string time_text(const std::tuple<long, long, long, long>& t) {
  std::ostringstream os;
  os << std::get<0>(t) << " " << std::get<1>(t) << " step " << std::get<3>(t);
  if (std::get<2>(t) != std::get<3>(t)) os << " (from " << std::get<2>(t) << ")";
  return os.str();
}

// GRIB 1 sections (3-byte lengths) in order: product definition, then the grid and bitmap
// sections where the product's flag octet says so, then the binary data; each at least its fixed
// header and inside the message before "7777". ecCodes aborts the process (an assertion in its
// bitmap accessor) on a bitmap section shorter than its 6-byte header.
template <class Number, class Fail>
void check_grib1_sections(int index, uint64_t start, uint64_t length, Number number, Fail fail) {
  const uint64_t end = start + length - 4;
  uint64_t at = start + 8;
  auto section = [&](const char* name, uint64_t minimum) {
    const uint64_t bytes = at + 3 <= end ? number(at, 3) : 0;
    if (bytes < minimum || bytes > end - at)
      fail(index, start, std::string(name) + " section at byte " + std::to_string(at - start) + " claims " +
                             std::to_string(bytes) + " bytes (at least " + std::to_string(minimum) +
                             ", within the message's " + std::to_string(length) + ")");
    at += bytes;
  };
  const uint64_t flags = at + 8 <= end ? number(at + 7, 1) : 0;
  section("product definition", 28);
  if (flags & 0x80) section("grid description", 6);
  if (flags & 0x40) section("bitmap", 6);
  section("binary data", 11);
}

// GRIB 2's section order: 1, optionally 2, then 3, 4, 5, 6, 7, where the runs 2-7, 3-7 or 4-7
// may repeat (several fields in one message). A message out of this order made ecCodes 2.28
// build accessors without end (gigabytes within seconds, found by fuzz_grib).
bool grib2_section_may_follow(uint64_t previous, uint64_t id) {
  switch (previous) {
    case 0: return id == 1;
    case 1: return id == 2 || id == 3;
    case 7: return id == 2 || id == 3 || id == 4;
    default: return id == previous + 1;
  }
}

// The framing of every message, checked before ecCodes sees the file: ecCodes trusts section
// lengths, and a hostile message whose section claims to run past the message's end makes it
// return fields without end (gigabytes from a 2 KB file, then a double free). A message starts
// at "GRIB" (junk between messages is skipped, as ecCodes does); GRIB 2: its 8-byte length must
// fit the file, end in "7777", and its sections (4-byte length >= 5, number 1 to 7, in order) must
// tile it exactly; GRIB 1: its 3-byte length must fit the file and end in "7777", and its sections must
// fit it (ECMWF's large-message encoding, top bit set, is left to ecCodes).
void check_grib_framing(const ByteReader& read, uint64_t size, const std::string& file) {
  auto fail = [&](int index, uint64_t at, const std::string& what) {
    throw std::runtime_error(file + ": GRIB message " + std::to_string(index) + " (at byte " + std::to_string(at) +
                             "): " + what);
  };
  auto number = [&](uint64_t at, int bytes) {
    unsigned char b[8] = {};
    if (at > size || uint64_t(bytes) > size - at || !read(at, uint64_t(bytes), reinterpret_cast<char*>(b))) return ~uint64_t(0);
    uint64_t v = 0;
    for (int i = 0; i < bytes; ++i) v = (v << 8) | b[i];
    return v;
  };
  auto ends_in_7777 = [&](uint64_t end) { return end >= 4 && number(end - 4, 4) == 0x37373737u; };
  std::vector<char> window(uint64_t(1) << 16);
  uint64_t pos = 0;
  for (int index = 1;; ++index) {
    // The next "GRIB" at or after pos.
    uint64_t start = size;
    for (uint64_t at = pos; at + 4 <= size && start == size;) {
      const uint64_t n = std::min<uint64_t>(window.size(), size - at);
      if (!read(at, n, window.data())) return;
      const std::string_view w(window.data(), n);
      const size_t hit = w.find("GRIB");
      if (hit != std::string_view::npos) start = at + hit;
      else at += n > 3 ? n - 3 : n;  // a magic split across windows is found next time
    }
    if (start + 8 > size) return;
    const uint64_t edition = number(start + 7, 1);
    uint64_t length = 0;
    if (edition == 2) {
      length = number(start + 8, 8);
      if (length < 16 + 4 || length > size - start) fail(index, start, "claims " + std::to_string(length) + " bytes, the file has " + std::to_string(size - start) + " from there");
      if (!ends_in_7777(start + length)) fail(index, start, "does not end in 7777 where its length says");
      uint64_t at = start + 16, previous = 0;
      while (at < start + length - 4) {
        const uint64_t section = number(at, 4), id = number(at + 4, 1);
        if (section < 5 || section > start + length - 4 - at || id < 1 || id > 7)
          fail(index, start, "section " + std::to_string(id) + " at byte " + std::to_string(at - start) + " claims " +
                                 std::to_string(section) + " bytes, past the message's end");
        if (!grib2_section_may_follow(previous, id))
          fail(index, start, "section " + std::to_string(id) + " at byte " + std::to_string(at - start) +
                                 (previous ? " follows section " + std::to_string(previous) : " comes first") +
                                 ", out of GRIB 2's order");
        previous = id;
        at += section;
      }
      if (previous != 7) fail(index, start, "ends after section " + std::to_string(previous) + ", not after section 7");
    } else if (edition == 1) {
      length = number(start + 4, 3);
      if (length & 0x800000) length = 0;  // ECMWF large message: ecCodes decides
      else if (length < 8 + 4 || length > size - start || !ends_in_7777(start + length))
        fail(index, start, "claims " + std::to_string(length) + " bytes, which do not fit the file or end in 7777");
      else
        check_grib1_sections(index, start, length, number, fail);
    }
    pos = start + std::max<uint64_t>(length, 4);
  }
}

// A GRIB file on disk, or its bytes in memory (through fmemopen: ecCodes reads a FILE*).
struct GribSource {
  std::string name;
  std::unique_ptr<FILE, int (*)(FILE*)> file{nullptr, &std::fclose};
  uint64_t size = 0;  // bytes of the file (0: unknown)

  explicit GribSource(const std::filesystem::path& path) : name(path.string()) {
    file.reset(std::fopen(name.c_str(), "rb"));
    if (!file) throw std::runtime_error(name + ": cannot open");
    std::error_code ec;
    size = std::filesystem::file_size(path, ec);
    if (ec) size = 0;
    FILE* f = file.get();
    check_grib_framing(
        [f](uint64_t offset, uint64_t n, char* out) {
          return fseeko(f, off_t(offset), SEEK_SET) == 0 && std::fread(out, 1, n, f) == n;
        },
        size, name);
    std::rewind(f);
  }
  GribSource(std::string_view bytes, std::string name_) : name(std::move(name_)), size(bytes.size()) {
    if (bytes.empty()) throw std::runtime_error(name + ": empty file");
    check_grib_framing(
        [bytes](uint64_t offset, uint64_t n, char* out) {
          if (offset > bytes.size() || n > bytes.size() - offset) return false;
          std::memcpy(out, bytes.data() + offset, n);
          return true;
        },
        bytes.size(), name);
    file.reset(::fmemopen(const_cast<char*>(bytes.data()), bytes.size(), "rb"));
    if (!file) throw std::runtime_error(name + ": cannot open in memory");
  }
};

// Reads every message's metadata; keeps the handles of messages whose shortName passes `keep`.
template <class Keep>
std::vector<Message> scan(const GribSource& source, Keep keep) {
  const std::string& file = source.name;
  FILE* f = source.file.get();
  std::vector<Message> out;
  int err = 0;
  // GRIB2 messages may hold several fields (NCEP packs u and v together); count each field.
  codes_grib_multi_support_on(nullptr);
  // Handles of a multi-field message can share ecCodes' buffer of it: the scan only ends inside a
  // message through an error ecCodes reports, never through an exception of tfmatch's.
  struct ResetMulti {
    FILE* f;
    ~ResetMulti() { codes_grib_multi_support_reset_file(nullptr, f); }
  } reset{f};
  // No cancellation checkpoint in this loop: unwinding from inside a multi-field message is
  // what the note above is about, and reading the metadata is quick; the values are read later.
  for (int index = 1;; ++index) {
    Handle h(codes_handle_new_from_file(nullptr, f, PRODUCT_GRIB, &err));
    if (!h) {
      if (err != CODES_SUCCESS)
        throw std::runtime_error(file + ": GRIB message " + std::to_string(index) + " is unreadable (" +
                                 codes_get_error_message(err) + ")");
      break;
    }
    Message m;
    m.index = index;
    m.short_name = get_string(h.get(), "shortName").value_or("unknown");
    if (!keep(m.short_name)) continue;
    m.level_type = get_string(h.get(), "typeOfLevel").value_or("unknown");
    m.level = signed_level(h.get(), get_double(h.get(), "level").value_or(0), "scaledValueOfFirstFixedSurface");
    m.bottom = get_double(h.get(), "bottomLevel").has_value()
                   ? signed_level(h.get(), *get_double(h.get(), "bottomLevel"), "scaledValueOfSecondFixedSurface")
                   : m.level;
    m.time = {get_long(h.get(), "dataDate").value_or(0), get_long(h.get(), "dataTime").value_or(0),
              get_long(h.get(), "startStep").value_or(0), get_long(h.get(), "endStep").value_or(0)};
    m.member = get_long(h.get(), "number").value_or(0);
    m.grid_type = get_string(h.get(), "gridType").value_or("unknown");
    m.ni = get_long(h.get(), "Ni").value_or(0);
    m.nj = get_long(h.get(), "Nj").value_or(0);
    m.corners = {get_double(h.get(), "latitudeOfFirstGridPointInDegrees").value_or(0),
                 get_double(h.get(), "longitudeOfFirstGridPointInDegrees").value_or(0),
                 get_double(h.get(), "latitudeOfLastGridPointInDegrees").value_or(0),
                 get_double(h.get(), "longitudeOfLastGridPointInDegrees").value_or(0)};
    m.handle = std::move(h);
    out.push_back(std::move(m));
  }
  return out;
}

std::array<double, 2> horizontal_spacing(const Message& m) {
  codes_handle* h = m.handle.get();
  std::array<double, 2> s{1, 1};
  if (m.grid_type == "regular_ll" || m.grid_type == "rotated_ll" || m.grid_type == "regular_gg") {
    s[0] = get_double(h, "iDirectionIncrementInDegrees").value_or(1.0);
    if (m.grid_type == "regular_gg") s[1] = m.nj > 1 ? std::abs(m.corners[0] - m.corners[2]) / double(m.nj - 1) : 1.0;
    else s[1] = get_double(h, "jDirectionIncrementInDegrees").value_or(1.0);
  } else {
    auto dx = get_double(h, "DxInMetres");
    auto dy = get_double(h, "DyInMetres");
    if (!dx) dx = get_double(h, "DiInMetres");
    if (!dy) dy = get_double(h, "DjInMetres");
    if (dx && dy) s = {*dx, *dy};
  }
  for (double& v : s)
    if (!std::isfinite(v) || v <= 0) v = 1.0;
  return s;
}

// Values of one message, missing points as NaN.
std::vector<double> message_values(const Message& m, const std::string& file) {
  codes_handle* h = m.handle.get();
  const std::string where = file + ": message " + std::to_string(m.index) + " (" + m.short_name + ")";
  if (codes_set_double(h, "missingValue", kMissing) != CODES_SUCCESS)
    throw std::runtime_error(where + ": cannot set missingValue");
  size_t n = 0;
  if (codes_get_size(h, "values", &n) != CODES_SUCCESS) throw std::runtime_error(where + ": has no values");
  if (m.ni <= 0 || m.nj <= 0 || n != size_t(m.ni) * size_t(m.nj))
    throw std::runtime_error(where + ": " + m.grid_type + " grid with " + std::to_string(n) +
                             " values is not a rectangular Ni x Nj grid (reduced grids are not supported)");
  check_memory(uint64_t(n) * sizeof(double), where + ": " + std::to_string(n) + " values");
  // ecCodes allocates the coded values by the count the data representation section states
  // (numberOfValues), not by the grid's: a hostile count made it ask for 2 GiB for a 12-point
  // grid (found by fuzz_grib). With a bitmap fewer values are coded than the grid has, never more.
  if (const std::optional<long> coded = get_long(h, "numberOfValues"); coded && (*coded < 0 || uint64_t(*coded) > n))
    throw std::runtime_error(where + ": states " + std::to_string(*coded) + " coded values for a grid of " +
                             std::to_string(n) + " points");
  std::vector<double> v(n);
  int err = codes_get_double_array(h, "values", v.data(), &n);
  if (err != CODES_SUCCESS) throw std::runtime_error(where + ": cannot decode values (" + codes_get_error_message(err) + ")");
  for (double& x : v)
    if (x == kMissing) x = NAN;
  return v;
}

template <class T, class F>
std::vector<T> distinct_sorted(const std::vector<Message>& ms, F get) {
  std::set<T> s;
  for (const auto& m : ms) s.insert(get(m));
  return {s.begin(), s.end()};
}

// The messages of the parameter and level type `options` select (every time and member).
struct Selection {
  std::vector<Message> messages;
  std::string parameter, level_type;
};

Selection select_messages(const GribSource& source, const VolumeOptions& options) {
  const std::string& file = source.name;
  std::string want = options.variable, want_level;
  if (auto at = want.find('@'); at != std::string::npos) {
    want_level = want.substr(at + 1);
    want = want.substr(0, at);
  }
  std::set<std::string> all_names;
  std::vector<Message> msgs = scan(source, [&](const std::string& n) {
    all_names.insert(n);
    return want.empty() || n == want;
  });
  auto names_list = [&] {
    std::string s;
    for (const auto& n : all_names) s += (s.empty() ? "" : ", ") + n;
    return s;
  };
  if (all_names.empty()) throw std::runtime_error(file + ": no GRIB messages (not a GRIB file?)");
  if (want.empty()) {
    if (all_names.size() != 1)
      throw std::runtime_error(file + ": choose a parameter (file.grib2:SHORTNAME or " + parameter("var") + "): " + names_list());
    want = *all_names.begin();
  }
  if (msgs.empty()) throw std::runtime_error(file + ": no parameter '" + want + "' (parameters: " + names_list() + ")");
  // Level type: the requested one, else the one with the most distinct levels.
  std::map<std::string, std::set<std::pair<double, double>>> levels_by_type;
  for (const auto& m : msgs) levels_by_type[m.level_type].insert({m.level, m.bottom});
  if (want_level.empty()) {
    size_t best = 0;
    for (const auto& m : msgs)
      if (levels_by_type[m.level_type].size() > best) best = levels_by_type[m.level_type].size(), want_level = m.level_type;
  } else if (!levels_by_type.count(want_level)) {
    std::string types;
    for (const auto& [t, l] : levels_by_type) types += (types.empty() ? "" : ", ") + t;
    throw std::runtime_error(file + ": parameter " + want + " has no level type '" + want_level + "' (it has: " + types + ")");
  }
  std::erase_if(msgs, [&](const Message& m) { return m.level_type != want_level; });
  return {std::move(msgs), want, want_level};
}

// Longitudes (x) and latitudes (y) of a regular or Gaussian grid, from its corners.
void set_horizontal_axes(Volume& v, const Message& m) {
  if (m.grid_type != "regular_ll" && m.grid_type != "regular_gg") return;
  for (int k = 0; k < 2; ++k) {
    const long n = k == 0 ? m.ni : m.nj;
    const double first = m.corners[k == 0 ? 1 : 0], last = m.corners[k == 0 ? 3 : 2];
    GridAxis& a = v.axes[k];
    a.name = k == 0 ? "longitude" : "latitude";
    a.units = k == 0 ? "degrees_east" : "degrees_north";
    a.coordinates.resize(size_t(n));
    double span = last - first;
    if (k == 0 && span < 0) span += 360.0;  // a grid crossing the date line / meridian 0
    for (long i = 0; i < n; ++i) a.coordinates[size_t(i)] = n > 1 ? first + span * double(i) / double(n - 1) : first;
    v.origin[k] = first;
  }
}

// The z axis of a level type, without coordinates.
GridAxis level_axis(const std::string& level_type) {
  GridAxis a;
  a.name = level_type;
  if (level_type == "isobaricInhPa") a.units = "hPa";
  if (level_type == "isobaricInPa") a.units = "Pa";
  return a;
}

Volume read_grib(const GribSource& source, const VolumeOptions& options) {
  const std::string& file = source.name;
  Selection sel = select_messages(source, options);
  std::vector<Message>& msgs = sel.messages;
  const std::string& want = sel.parameter;
  const std::string& want_level = sel.level_type;
  const auto times = distinct_sorted<std::tuple<long, long, long, long>>(msgs, [](const Message& m) { return m.time; });
  const auto members = distinct_sorted<long>(msgs, [](const Message& m) { return m.member; });
  const std::string what = file + ": " + want + "@" + want_level;
  const uint64_t t = options.time_index.value_or(0), k = options.member_index.value_or(0);
  if (t >= times.size())
    throw std::runtime_error(what + ": time " + std::to_string(t) + " is out of range (" + std::to_string(times.size()) +
                             " reference time/step pairs)");
  if (k >= members.size())
    throw std::runtime_error(what + ": member " + std::to_string(k) + " is out of range (" + std::to_string(members.size()) +
                             " ensemble members)");
  std::erase_if(msgs, [&](const Message& m) { return m.time != times[t] || m.member != members[k]; });
  std::stable_sort(msgs.begin(), msgs.end(),
                   [](const Message& a, const Message& b) { return std::tie(a.level, a.bottom) < std::tie(b.level, b.bottom); });
  for (size_t i = 1; i < msgs.size(); ++i) {
    if (msgs[i].level == msgs[i - 1].level && msgs[i].bottom == msgs[i - 1].bottom)
      throw std::runtime_error(what + ": messages " + std::to_string(msgs[i - 1].index) + " and " + std::to_string(msgs[i].index) +
                               " are both at level " + std::to_string(msgs[i].level) + " (differing in a key not selected, e.g. stepType)");
    if (!msgs[i].same_grid(msgs[0]))
      throw std::runtime_error(what + ": the messages do not share one grid: message " + std::to_string(msgs[0].index) + " is " +
                               msgs[0].grid_text() + ", message " + std::to_string(msgs[i].index) + " is " + msgs[i].grid_text());
  }
  Volume v;
  v.dims = {uint64_t(std::max<long>(msgs[0].ni, 0)), uint64_t(std::max<long>(msgs[0].nj, 0)), msgs.size()};
  checked_voxel_count(v.dims, file);
  const auto hs = horizontal_spacing(msgs[0]);
  v.spacing = {hs[0], hs[1], 1.0};
  set_horizontal_axes(v, msgs[0]);
  v.axes[2] = level_axis(want_level);
  for (const auto& m : msgs) v.axes[2].coordinates.push_back(m.level);
  v.name = file + ":" + want + "@" + want_level;
  v.units = get_string(msgs[0].handle.get(), "units").value_or("");
  if (v.units == "unknown" || v.units == "~") v.units.clear();  // ecCodes' words for none
  if (times.size() > 1) v.name += ",time=" + std::to_string(t);
  if (members.size() > 1) v.name += ",member=" + std::to_string(k);
  check_memory(v.voxel_count() * sizeof(float), what + ": " + std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) +
                                                   "x" + std::to_string(v.dims[2]) + " values");
  v.values.reserve(v.voxel_count());
  for (const auto& m : msgs) {
    checkpoint("load");
    std::vector<double> values = message_values(m, file);
    for (double x : values) v.values.push_back(static_cast<float>(x));
  }
  apply_world_orientation(v, world_orientation(v.axes, v.dims));
  return v;
}

FileInfo describe_grib(const GribSource& source) {
  const std::string& file = source.name;
  std::vector<Message> msgs = scan(source, [](const std::string&) { return true; });
  if (msgs.empty()) throw std::runtime_error(file + ": no GRIB messages (not a GRIB file?)");
  FileInfo info{file, "GRIB", {}, {}};
  std::set<long> editions;
  for (const auto& m : msgs) editions.insert(get_long(m.handle.get(), "edition").value_or(0));
  std::string ed;
  for (long e : editions) ed += (ed.empty() ? "" : ", ") + std::to_string(e);
  info.format = "GRIB edition " + ed + ", " + std::to_string(msgs.size()) + " messages";
  // One entry per (shortName, typeOfLevel), in order of first appearance.
  std::vector<std::pair<std::string, std::string>> order;
  std::map<std::pair<std::string, std::string>, std::vector<const Message*>> groups;
  for (const auto& m : msgs) {
    auto key = std::make_pair(m.short_name, m.level_type);
    if (!groups.count(key)) order.push_back(key);
    groups[key].push_back(&m);
  }
  for (const auto& key : order) {
    const auto& g = groups[key];
    ArrayInfo a;
    a.name = key.first + "@" + key.second;
    a.kind = "GRIB parameter";
    const Message& first = *g.front();
    a.type = get_string(first.handle.get(), "packingType").value_or("?");
    std::set<std::pair<double, double>> levels;
    std::set<std::tuple<long, long, long, long>> times;
    std::set<long> members;
    bool same_grid = true;
    for (const Message* m : g) {
      levels.insert({m->level, m->bottom});
      times.insert(m->time);
      members.insert(m->member);
      same_grid &= m->same_grid(first);
    }
    std::ostringstream shape;
    shape << g.size() << " messages, " << levels.size() << " levels (" << levels.begin()->first;
    if (levels.size() > 1) shape << " .. " << levels.rbegin()->first;
    shape << "), grid " << first.grid_text();
    a.shape = shape.str();
    if (same_grid && first.ni > 0 && first.nj > 0) {
      a.grid = {uint64_t(first.ni), uint64_t(first.nj), levels.size()};
      auto hs = horizontal_spacing(first);
      a.spacing = {hs[0], hs[1], 1.0};
      Volume grid;  // the axes as loaded, without values
      set_horizontal_axes(grid, first);
      grid.axes[2] = level_axis(key.second);
      for (const auto& l : levels) grid.axes[2].coordinates.push_back(l.first);
      const WorldOrientation o = world_orientation(grid.axes, a.grid);
      orient_axes(grid.axes, a.origin, a.spacing, o);
      a.orientation = orientation_lines(grid.axes, a.origin, a.spacing, o);
    } else {
      a.notes.push_back(same_grid ? "not a rectangular grid: cannot be loaded" : "messages on different grids: cannot be stacked");
    }
    if (times.size() > 1) a.choices.push_back(std::to_string(times.size()) + " times (" + parameter("time") + "): " + time_text(*times.begin()) +
                                              " .. " + time_text(*times.rbegin()));
    if (members.size() > 1) a.choices.push_back(std::to_string(members.size()) + " members (" + parameter("member") + "): number " +
                                                std::to_string(*members.begin()) + " .. " + std::to_string(*members.rbegin()));
    if (auto n = get_string(first.handle.get(), "name")) a.notes.push_back(*n);
    if (auto u = get_string(first.handle.get(), "units")) a.notes.push_back("units: " + *u);
    for (const Message* m : g) {
      if (m->ni <= 0 || m->nj <= 0) break;
      std::vector<double> v = message_values(*m, file);
      std::vector<float> f(v.begin(), v.end());
      accumulate_stats(a, f.data(), f.size());
    }
    info.arrays.push_back(std::move(a));
  }
  return info;
}

}  // namespace

uint64_t count_grib_members(const std::filesystem::path& path, const VolumeOptions& options) {
  const Selection sel = select_messages(GribSource(path), options);
  return distinct_sorted<long>(sel.messages, [](const Message& m) { return m.member; }).size();
}

Volume read_grib_volume(const std::filesystem::path& path, const VolumeOptions& options) {
  return read_grib(GribSource(path), options);
}

FileInfo describe_grib(const std::filesystem::path& path, const VolumeOptions&) { return describe_grib(GribSource(path)); }

Volume parse_grib(std::string_view bytes, const std::string& name, const VolumeOptions& options) {
  return read_grib(GribSource(bytes, name), options);
}

FileInfo describe_grib_bytes(std::string_view bytes, const std::string& name) {
  return describe_grib(GribSource(bytes, name));
}

}  // namespace tfm
