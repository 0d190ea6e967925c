// Ensembles read member by member through the format table (volume_format_table.h): each format
// knows how to select one member, so an ensemble needs no reader of its own.
#include "tfmatch/io/ensemble_io.h"

#include <glob.h>
#include <sys/resource.h>

#include <algorithm>
#include <limits>
#include <memory>
#include <stdexcept>

#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/phase_timer.h"

namespace tfm {
namespace {

std::string grid_text(const Volume& v) {
  return std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" + std::to_string(v.dims[2]);
}

void check_member_grid(const Ensemble& e, const Volume& member) {
  if (member.dims != e.grid.dims)
    throw std::runtime_error("ensemble members are on different grids: " + e.member_names.front() + " is " +
                             grid_text(e.grid) + ", " + member.name + " is " + grid_text(member));
}

// Appends member `v` to `e` (the first member sets the grid).
void add_member(Ensemble& e, Volume&& v, uint64_t expected_members) {
  if (e.member_count == 0) {
    e.grid = empty_like(v);
    const uint64_t voxels = v.voxel_count();
    if (voxels != 0 && expected_members > std::numeric_limits<uint64_t>::max() / voxels / sizeof(float))
      throw std::runtime_error(v.name + ": an ensemble of " + std::to_string(expected_members) + " members of " +
                               std::to_string(voxels) + " voxels is too large");
    check_memory(expected_members * voxels * sizeof(float),
                 v.name + ": an ensemble of " + std::to_string(expected_members) + " members of " + grid_text(v));
    e.values.reserve(expected_members * voxels);
  } else {
    check_member_grid(e, v);
  }
  e.values.insert(e.values.end(), v.values.begin(), v.values.end());
  e.member_names.push_back(v.name);
  ++e.member_count;
}

// Appends the member `spec` selects. Members after the first are read straight into their place
// in the ensemble's values where their format reads slabs (the same values, bit for bit:
// volume_slabs.h), instead of loaded into a volume of their own and copied (10 raw members of
// 1.76 M voxels on a 2-core machine: loading took 142 ms, now 115, medians of 6 runs). The first
// member is loaded whole: it sets the grid, with the axis coordinates a slab reader may leave out.
void add_member(Ensemble& e, const std::string& spec, const VolumeOptions& options, uint64_t expected_members) {
  if (e.member_count > 0) {
    if (std::unique_ptr<VolumeSlabReader> reader = open_volume_slabs(spec, options)) {
      PhaseScope timing(Phase::Read);
      check_member_grid(e, reader->grid());
      const uint64_t voxels = e.voxel_count(), at = e.values.size();
      e.values.resize(at + voxels);  // within the capacity the first member reserved
      reader->read_slices(0, e.grid.dims[2], e.values.data() + at);
      e.member_names.push_back(reader->grid().name);
      ++e.member_count;
      return;
    }
  }
  add_member(e, load_volume(spec, options), expected_members);
}

// The file, options and member count of an ensemble `spec` names along its member axis; throws
// "<file>: ..." when it has none, or names one member.
struct MemberAxis {
  std::string file;
  VolumeOptions options;
  uint64_t count = 0;
  // The ensemble as named in messages and outputs, with the time step read where one was chosen.
  std::string name() const {
    std::string n = file + (options.variable.empty() ? "" : ":" + options.variable);
    if (options.time_index) n += (options.variable.empty() ? ":time=" : ",time=") + std::to_string(*options.time_index);
    return n;
  }
};
MemberAxis member_axis(const std::string& spec, const VolumeOptions& defaults) {
  const VolumeSpec s = parse_volume_spec(spec, defaults);
  const std::string file = s.path.string();
  if (!std::filesystem::exists(s.path)) throw std::runtime_error(file + ": no such file");
  const VolumeFormat* format = find_volume_format(s.path);
  if (!format) throw std::runtime_error(unknown_volume_format_message(s.path));
  if (!format->has_members || !format->count_members)
    throw std::runtime_error(file + ": a " + format->title + " file has no member axis (ensembles come from " +
                             volume_format_titles(&VolumeFormat::has_members) + " files, or one file per member with " + parameter("members") + ")");
  if (s.options.member_index)
    throw std::runtime_error(file + ": ',member=N' / " + parameter("member") + " picks one member; an ensemble uses them all");
  const uint64_t count = format->count_members(s.path, s.options);
  if (count > std::numeric_limits<uint32_t>::max())
    throw std::runtime_error(file + ": " + std::to_string(count) + " members are more than tfmatch handles");
  MemberAxis axis{file, s.options, count};
  if (count == 1)
    throw std::runtime_error(
        axis.name() + ": one member only" +
        (s.options.member_dim.empty() && format->title == "NetCDF"
             ? ": the variable has no dimension besides time and the grid's (" + parameter("member-dim") +
                   " names the one that holds the members, e.g. " + parameter("member-dim") + " Time)"
             : "") +
        "; an ensemble needs at least 3 (or give one file per member with " + parameter("members") + ")");
  return axis;
}

}  // namespace

Ensemble load_ensemble(const std::string& spec, const VolumeOptions& defaults) {
  const MemberAxis axis = member_axis(spec, defaults);
  Ensemble e;
  for (uint64_t m = 0; m < axis.count; ++m) {
    VolumeOptions o = axis.options;
    o.member_index = m;
    add_member(e, axis.file, o, axis.count);
  }
  e.grid.name = axis.name();
  return e;
}

Ensemble load_ensemble_members(const std::vector<std::string>& specs, const VolumeOptions& options) {
  if (specs.size() > std::numeric_limits<uint32_t>::max()) throw std::runtime_error("too many member files");
  Ensemble e;
  for (const auto& spec : specs) add_member(e, spec, options, specs.size());
  if (!specs.empty()) e.grid.name = specs.front() + " .. " + specs.back();
  return e;
}

namespace {

// Every member open at once: one file descriptor each (more for NetCDF-4). The soft limit (often
// 1024) is raised to the hard one, which Linux sets far higher.
void raise_open_file_limit() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) == 0 && limit.rlim_cur < limit.rlim_max) {
    limit.rlim_cur = limit.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &limit);
  }
}

void add_reader(EnsembleSlabs& e, std::unique_ptr<VolumeSlabReader> reader, const std::string& name) {
  if (!e.members.empty() && reader->grid().dims != e.grid().dims)
    throw std::runtime_error("ensemble members are on different grids: " + e.member_names.front() + " is " +
                             grid_text(e.grid()) + ", " + name + " is " + grid_text(reader->grid()));
  e.members.push_back(std::move(reader));
  e.member_names.push_back(name);
}

}  // namespace

bool EnsembleSlabs::streams() const {
  for (const auto& m : members)
    if (!m->streams()) return false;
  return true;
}

// The member reader of `spec`, or nullptr when only streaming readers are wanted and it cannot stream.
static std::unique_ptr<VolumeSlabReader> open_member(const std::string& spec, const VolumeOptions& options, bool streaming_only) {
  return streaming_only ? open_volume_slabs(spec, options) : open_volume_slabs_or_load(spec, options);
}

EnsembleSlabs open_ensemble_slabs(const std::string& spec, const VolumeOptions& defaults, bool streaming_only) {
  const MemberAxis axis = member_axis(spec, defaults);
  raise_open_file_limit();
  EnsembleSlabs e;
  for (uint64_t m = 0; m < axis.count; ++m) {
    VolumeOptions o = axis.options;
    o.member_index = m;
    std::unique_ptr<VolumeSlabReader> reader = open_member(axis.file, o, streaming_only);
    if (!reader) return {};
    add_reader(e, std::move(reader), axis.file + " member " + std::to_string(m));
  }
  e.name = axis.name();
  return e;
}

EnsembleSlabs open_ensemble_member_slabs(const std::vector<std::string>& specs, const VolumeOptions& options,
                                         bool streaming_only) {
  if (specs.size() > std::numeric_limits<uint32_t>::max()) throw std::runtime_error("too many member files");
  raise_open_file_limit();
  EnsembleSlabs e;
  for (const auto& spec : specs) {
    std::unique_ptr<VolumeSlabReader> reader = open_member(spec, options, streaming_only);
    if (!reader) return {};
    add_reader(e, std::move(reader), spec);
  }
  if (!specs.empty()) e.name = specs.front() + " .. " + specs.back();
  return e;
}

namespace {

// a < b with runs of digits compared as numbers (leading zeros aside), the rest as bytes; names
// equal that way fall back to plain text order, so the order is total.
bool natural_less(const std::string& a, const std::string& b) {
  auto digit = [](char c) { return c >= '0' && c <= '9'; };
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (digit(a[i]) && digit(b[j])) {
      size_t ie = i, je = j;
      while (ie < a.size() && digit(a[ie])) ++ie;
      while (je < b.size() && digit(b[je])) ++je;
      size_t is = i, js = j;  // past leading zeros
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      if (const int c = a.compare(is, ie - is, b, js, je - js); c != 0) return c < 0;
      i = ie, j = je;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i, ++j;
    }
  }
  if (i < a.size() || j < b.size()) return j < b.size();  // one is a prefix of the other
  return a < b;
}

}  // namespace

std::vector<std::string> match_files(const std::string& pattern) {
  // glob(3) from the C library: the shell's own pattern rules.
  glob_t g{};
  const int rc = ::glob(pattern.c_str(), GLOB_ERR, nullptr, &g);
  std::unique_ptr<glob_t, void (*)(glob_t*)> guard(&g, ::globfree);
  if (rc == GLOB_NOMATCH) return {};
  if (rc != 0) throw std::runtime_error(pattern + ": cannot expand the pattern (a directory is unreadable)");
  std::vector<std::string> out(g.gl_pathv, g.gl_pathv + g.gl_pathc);
  std::sort(out.begin(), out.end(), natural_less);
  return out;
}

std::vector<std::string> expand_member_patterns(const std::vector<std::string>& args) {
  std::vector<std::string> out;
  for (const auto& a : args) {
    if (a.find_first_of("*?[") == std::string::npos) {
      out.push_back(a);
      continue;
    }
    const std::vector<std::string> files = match_files(a);
    if (files.empty()) throw std::runtime_error(a + ": the pattern matches no file");
    out.insert(out.end(), files.begin(), files.end());
  }
  return out;
}

}  // namespace tfm
