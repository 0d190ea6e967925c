// load_volume(): parses "path:SELECTION", finds the file's row of the format table (extension, else
// the first bytes), checks the selection against what that format has and calls its reader.
#include <charconv>
#include <exception>
#include <future>
#include <optional>
#include <stdexcept>
#include <utility>

#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch/model/volume.h"

namespace tfm {
namespace {

// SELECTION = VAR[@LEVELTYPE][,time=N][,member=N] (VAR may be empty: "file.nc:,time=2").
void apply_selection(const std::string& selection, const std::string& file, VolumeOptions& o) {
  size_t comma = selection.find(',');
  // Array names may contain '[' ']' for components; only ",key=N" parts are options.
  std::string var = selection.substr(0, comma);
  if (!var.empty()) o.variable = var;
  bool seen_time = false, seen_member = false;  // a key given twice: which one was meant?
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
    bool& seen = key == "time" ? seen_time : seen_member;
    if (seen) throw std::runtime_error(file + ": bad selection: " + key + " is given twice");
    seen = true;
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

namespace {

// The format of the file `path`, after checking that it exists and that `options` select only
// what the format has.
const VolumeFormat& checked_format(const std::filesystem::path& path, const VolumeOptions& options) {
  if (!std::filesystem::exists(path)) throw std::runtime_error(path.string() + ": no such file");
  if (std::filesystem::is_directory(path)) throw std::runtime_error(path.string() + ": is a directory, not a volume file");
  const VolumeFormat* format = find_volume_format(path);
  if (!format) throw std::runtime_error(unknown_volume_format_message(path));
  // Options that only some formats understand are errors elsewhere, not silently ignored (index 0
  // is what --time/--member give by default, so it passes).
  if (!format->has_times && options.time_index && *options.time_index > 0)
    throw std::runtime_error(path.string() + ": time selection (,time=N / " + parameter("time") + ") applies to " +
                             volume_format_titles(&VolumeFormat::has_times) + " files only; a " + format->title +
                             " file has no time axis");
  if (!format->has_members && options.member_index && *options.member_index > 0)
    throw std::runtime_error(path.string() + ": member selection (,member=N / " + parameter("member") + ") applies to " +
                             volume_format_titles(&VolumeFormat::has_members) + " files only; a " + format->title +
                             " file has no member axis");
  if (!format->has_variables() && !format->has_components && !options.variable.empty())
    throw std::runtime_error(path.string() + ": a " + format->name + " file holds one array; remove ':" +
                             options.variable + "' / " + parameter("var"));
  return *format;
}

}  // namespace

Volume load_volume(const std::string& spec, const VolumeOptions& defaults) {
  PhaseScope timing(Phase::Read);
  VolumeSpec s = parse_volume_spec(spec, defaults);
  const std::filesystem::path& path = s.path;
  const VolumeOptions& options = s.options;
  Volume v = checked_format(path, options).read(path, options);
  if (v.voxel_count() == 0 || v.values.size() != v.voxel_count())
    throw std::runtime_error(path.string() + ": the volume is empty");
  return v;
}

namespace {

// The voxel count of `spec` from its header when its format may be read beside another file;
// nullopt when it may not or the header does not say (a compressed VTI).
std::optional<uint64_t> concurrent_voxel_count(const std::string& spec, const VolumeOptions& defaults) {
  const VolumeSpec s = parse_volume_spec(spec, defaults);
  const VolumeFormat& format = checked_format(s.path, s.options);
  if (!format.concurrent_reads || !format.open_slabs) return std::nullopt;
  const std::unique_ptr<VolumeSlabReader> r = format.open_slabs(s.path, s.options);
  if (!r) return std::nullopt;
  return r->grid().voxel_count();
}

}  // namespace

std::pair<Volume, Volume> load_volume_pair(const std::string& first, const std::string& second,
                                           const VolumeOptions& options) {
  PhaseScope timing(Phase::Read);
  const std::optional<uint64_t> n_first = concurrent_voxel_count(first, options);
  const std::optional<uint64_t> n_second = n_first ? concurrent_voxel_count(second, options) : std::nullopt;
  if (!n_first || !n_second) {
    Volume a = load_volume(first, options);
    return {std::move(a), load_volume(second, options)};
  }
  // Each reader checks its own volume against the budget; side by side, neither sees what the
  // other is about to allocate, so both are checked together first.
  check_memory((*n_first + *n_second) * sizeof(float), first + " and " + second + ": reading both (decoded as float32)");
  std::future<Volume> b = std::async(std::launch::async, [&] {
    const UntimedThread overlapped;  // this thread's time is the waiting one's
    return load_volume(second, options);
  });
  Volume a;
  std::exception_ptr a_error;
  try {
    a = load_volume(first, options);
  } catch (...) {
    a_error = std::current_exception();
  }
  Volume vb;
  std::exception_ptr b_error;
  try {
    vb = b.get();  // waited for even after the first failed: the thread refers to this frame
  } catch (...) {
    b_error = std::current_exception();
  }
  if (a_error) std::rethrow_exception(a_error);
  if (b_error) std::rethrow_exception(b_error);
  return {std::move(a), std::move(vb)};
}

std::unique_ptr<VolumeSlabReader> open_volume_slabs(const std::string& spec, const VolumeOptions& defaults) {
  VolumeSpec s = parse_volume_spec(spec, defaults);
  const VolumeFormat& format = checked_format(s.path, s.options);
  if (!format.open_slabs) return nullptr;
  std::unique_ptr<VolumeSlabReader> r = format.open_slabs(s.path, s.options);
  if (r && r->grid().voxel_count() == 0) throw std::runtime_error(s.path.string() + ": the volume is empty");
  return r;
}

std::unique_ptr<VolumeSlabReader> open_volume_slabs_or_load(const std::string& spec, const VolumeOptions& options) {
  if (std::unique_ptr<VolumeSlabReader> r = open_volume_slabs(spec, options)) return r;
  return slabs_in_memory(load_volume(spec, options));
}

}  // namespace tfm
