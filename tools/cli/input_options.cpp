// Input flags of the TF-fitting subcommands and their loading.
#include "input_options.h"

#include <charconv>
#include <iostream>
#include <optional>
#include <sstream>
#include <tuple>

#include "cli.h"
#include "tfmatch/io/ensemble_io.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_io.h"

namespace tfm::cli {

void add_input_options(CLI::App* sub, InputArgs& a, bool required) {
  auto* ref = sub->add_option("--ref", a.ref, "Reference field: FILE or FILE:VAR[@LEVELTYPE][,time=N][,member=N]");
  auto* tf = sub->add_option("--ref-tf", a.ref_tf, "Reference transfer function: tfmatch JSON, framework XML or "
                             "ParaView preset (FILE:PRESET picks one), or a built-in map: " + builtin_tf_syntax() +
                             " (a file of that name wins)");
  auto* field = sub->add_option("--field", a.field, "Field whose transfer function is optimized");
  if (required) {
    ref->required();
    tf->required();
    field->required();
  }
  sub->add_option("--tf-size", a.tf_size, "Entries N of the optimized TF")->check(CLI::Range(2u, uint32_t(kMaxTableSize)))
      ->capture_default_str();
  sub->add_option("--ref-range", a.ref_range, "Reference field range lo,hi (default: TF file's, else finite min/max)");
  sub->add_option("--field-range", a.field_range, "Field range lo,hi (default: finite min/max)");
  add_allow_out_of_range_flag(sub, a.allow_out_of_range);
  add_volume_flags(sub, a.volume);
}

void reject_input_flags(const InputArgs& a, const std::string& instead) {
  const VolumeFlags& v = a.volume;
  const std::pair<bool, const char*> given[] = {
      {!a.ref_range.empty(), "--ref-range"}, {!a.field_range.empty(), "--field-range"},
      {a.allow_out_of_range, "--allow-out-of-range"}, {!v.dims.empty(), "--dims"}, {!v.type.empty(), "--type"},
      {v.big_endian, "--big-endian"}, {!v.var.empty(), "--var"}, {v.time.has_value(), "--time"},
      {v.member.has_value(), "--member"}};
  for (const auto& [is_given, flag] : given)
    if (is_given)
      throw CLI::ValidationError(flag, "describes the input files, and " + instead + "; remove it");
}

namespace {

// CLI::ValidationError for `flag` when no input's format `takes` it.
void check_described(const std::string& flag, bool VolumeFormat::*takes, const std::vector<std::string>& inputs) {
  std::string seen;  // "a.nc (NetCDF), b.vti (VTI)"
  for (const std::string& spec : inputs) {
    const std::filesystem::path path = parse_volume_spec(spec, {}).path;
    const VolumeFormat* format = find_volume_format(path);
    if (!format || format->*takes) return;  // an unknown format is its reader's error
    if (seen.size() < 200) seen += (seen.empty() ? "" : ", ") + path.filename().string() + " (" + format->title + ")";
  }
  const std::string formats = volume_format_titles(takes, " and ");
  throw CLI::ValidationError(flag, "describes " + formats + " files, and no input is one" +
                                       (seen.empty() ? std::string() : ": " + seen) + "; remove it");
}

}  // namespace

VolumeOptions VolumeFlags::options(const std::vector<std::string>& inputs) const {
  if (!dims.empty()) check_described("--dims", &VolumeFormat::takes_layout, inputs);
  if (!type.empty()) check_described("--type", &VolumeFormat::takes_layout, inputs);
  if (big_endian) check_described("--big-endian", &VolumeFormat::takes_byte_order, inputs);
  VolumeOptions vo;
  if (dims.size() == 3) vo.dims = std::array<uint64_t, 3>{dims[0], dims[1], dims[2]};
  if (!type.empty()) {
    vo.type = parse_scalar_type(type);
    if (vo.type == ScalarType::Unknown)  // a bad option value: a usage error, as --dims 0 is
      throw CLI::ValidationError("--type", "unknown element type '" + type +
                                               "' (uint8, int8, uint16, int16, uint32, int32, float32, float64, ...)");
  }
  vo.big_endian = big_endian;
  vo.variable = var;
  vo.time_index = time;
  vo.member_index = member;
  return vo;
}

void add_volume_flags(CLI::App* sub, VolumeFlags& f, FieldSelectors selectors) {
  const std::string raw = "Raw volumes";
  sub->add_option("--dims", f.dims, "Raw files: grid size X,Y,Z (when the file name does not say)")->expected(3)
      ->delimiter(',')->check(positive_integer())->group(raw);
  sub->add_option("--type", f.type, "Raw files: element type (uint8, uint16, int16, float32, float64, ...)")->group(raw);
  sub->add_flag("--big-endian", f.big_endian, "Raw and .dat files: big-endian data")->group(raw);
  // Which formats have variables, times and members comes from the format table.
  const std::string selection = "Field selection";
  sub->add_option("--var", f.var, volume_format_selectors() + ", for every field unless FILE:VAR says otherwise")
      ->group(selection);
  sub->add_option("--time", f.time, "Time index, " + volume_format_titles(&VolumeFormat::has_times) +
                  " files (default 0; FILE:VAR,time=N per field)")->group(selection);
  if (selectors == FieldSelectors::VarTimeMember)
    sub->add_option("--member", f.member, "Ensemble member / extra dimension index, " +
                    volume_format_titles(&VolumeFormat::has_members) + " files (default 0; FILE:VAR,member=N per field)")
        ->group(selection);
}

void load_inputs(const InputArgs& a, LoadedInputs& out) {
  const VolumeOptions vo = a.volume.options({a.ref, a.field});
  std::tie(out.ref, out.field) = load_volume_pair(a.ref, a.field, vo);
  out.request.ref = &out.ref;
  out.request.field = &out.field;
  load_tf_and_ranges(a, out.request);
}

void load_tf_and_ranges(const InputArgs& a, FitSettings& req) {
  std::vector<std::string> notes;
  req.ref_tf = read_transfer_function(a.ref_tf, {}, &notes);
  for (const auto& n : notes) print_note(n);
  if (!a.ref_range.empty()) req.ref_range = parse_range(a.ref_range, "--ref-range");
  if (!a.field_range.empty()) req.field_range = parse_range(a.field_range, "--field-range");
  req.tf_size = a.tf_size;
  req.allow_out_of_range = a.allow_out_of_range;
}

namespace {
// A FILE or FILE:VAR... spec with an absolute FILE (a relative one is resolved against `base`).
std::string absolute_spec(const std::string& spec, const std::filesystem::path& base) {
  if (spec.empty()) return spec;
  const std::filesystem::path p(spec);
  return p.is_absolute() ? spec : (std::filesystem::absolute(base) / p).lexically_normal().string();
}
// A TF spec as absolute_spec() makes it, except a built-in map's name, which stays a name.
std::string absolute_tf_spec(const std::string& spec, const std::filesystem::path& base) {
  bool builtin = false;
  try {
    builtin = !spec.empty() && parse_builtin_tf(spec);
  } catch (const std::invalid_argument&) {
    builtin = true;  // a built-in name with a bad option: kept as typed, for its reader's message
  }
  return builtin && !std::filesystem::exists(std::filesystem::absolute(base) / spec) ? spec : absolute_spec(spec, base);
}
}  // namespace

namespace {

// "key=A..B" as (key, A, B), or nothing when `part` is not a range.
std::optional<std::tuple<std::string, uint64_t, uint64_t>> selection_range(const std::string& part,
                                                                          const std::string& spec,
                                                                          const std::string& flag) {
  const size_t eq = part.find('='), dots = part.find("..");
  if (eq == std::string::npos || dots == std::string::npos) return std::nullopt;
  const std::string key = part.substr(0, eq), lo = part.substr(eq + 1, dots - eq - 1), hi = part.substr(dots + 2);
  auto number = [&](const std::string& text) {
    uint64_t n = 0;
    auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), n);
    if (text.empty() || ec != std::errc() || p != text.data() + text.size())
      throw CLI::ValidationError(flag, spec + ": bad range '" + part + "' (expected time=A..B or member=A..B)");
    return n;
  };
  if (key != "time" && key != "member")
    throw CLI::ValidationError(flag, spec + ": a range selects times or members ('" + part + "')");
  const uint64_t a = number(lo), b = number(hi);
  if (b < a) throw CLI::ValidationError(flag, spec + ": empty range '" + part + "' (" + hi + " < " + lo + ")");
  if (b - a >= 100000) throw CLI::ValidationError(flag, spec + ": range '" + part + "' names over 100000 fields");
  return std::tuple{key, a, b};
}

}  // namespace

std::vector<std::string> expand_field_specs(const std::vector<std::string>& specs, const std::string& flag) {
  std::vector<std::string> out;
  for (const std::string& spec : specs) {
    std::string path = spec, selection;
    if (!std::filesystem::exists(spec)) {
      const size_t colon = spec.rfind(':');
      if (colon != std::string::npos && colon > 0) path = spec.substr(0, colon), selection = spec.substr(colon + 1);
    }
    std::vector<std::string> paths{path};
    if (path.find_first_of("*?[") != std::string::npos && !std::filesystem::exists(path)) {
      paths = match_files(path);
      if (paths.empty()) throw CLI::ValidationError(flag, "'" + path + "' matches no file");
    }
    // The selection's parts, one of which may be a range.
    std::vector<std::string> parts;
    std::istringstream split(selection);
    for (std::string part; std::getline(split, part, ',');) parts.push_back(part);
    size_t range_part = parts.size();
    std::tuple<std::string, uint64_t, uint64_t> range{"", 0, 0};
    for (size_t k = 0; k < parts.size(); ++k)
      if (auto r = selection_range(parts[k], spec, flag)) {
        if (range_part != parts.size()) throw CLI::ValidationError(flag, spec + ": one range per field spec");
        range_part = k;
        range = *r;
      }
    for (const std::string& p : paths) {
      if (range_part == parts.size()) {
        out.push_back(selection.empty() ? p : p + ":" + selection);
        continue;
      }
      for (uint64_t n = std::get<1>(range); n <= std::get<2>(range); ++n) {
        std::string sel;
        for (size_t k = 0; k < parts.size(); ++k)
          sel += (k ? "," : "") + (k == range_part ? std::get<0>(range) + "=" + std::to_string(n) : parts[k]);
        out.push_back(p + ":" + sel);
      }
    }
  }
  return out;
}

nlohmann::json input_args_json(const InputArgs& a) {
  const std::filesystem::path cwd = std::filesystem::current_path();
  nlohmann::json j = {{"ref", absolute_spec(a.ref, cwd)},
                      {"field", absolute_spec(a.field, cwd)},
                      {"ref_tf", absolute_tf_spec(a.ref_tf, cwd)},
                      {"tf_size", a.tf_size},
                      {"ref_range", a.ref_range},
                      {"field_range", a.field_range},
                      {"allow_out_of_range", a.allow_out_of_range},
                      {"dims", a.volume.dims},
                      {"type", a.volume.type},
                      {"big_endian", a.volume.big_endian},
                      {"var", a.volume.var}};
  if (a.volume.time) j["time"] = *a.volume.time;
  if (a.volume.member) j["member"] = *a.volume.member;
  return j;
}

InputArgs input_args_from_json(const nlohmann::json& j, const std::filesystem::path& base) {
  InputArgs a;
  auto text = [&](const char* key) { return j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : std::string(); };
  a.ref = absolute_spec(text("ref"), base);
  a.field = absolute_spec(text("field"), base);
  a.ref_tf = absolute_tf_spec(text("ref_tf"), base);
  a.tf_size = j.value("tf_size", 64u);
  a.ref_range = text("ref_range");
  a.field_range = text("field_range");
  a.allow_out_of_range = j.value("allow_out_of_range", false);
  if (j.contains("dims") && j["dims"].is_array()) a.volume.dims = j["dims"].get<std::vector<uint64_t>>();
  a.volume.type = text("type");
  a.volume.big_endian = j.value("big_endian", false);
  a.volume.var = text("var");
  if (j.contains("time") && j["time"].is_number_unsigned()) a.volume.time = j["time"].get<uint64_t>();
  if (j.contains("member") && j["member"].is_number_unsigned()) a.volume.member = j["member"].get<uint64_t>();
  return a;
}

void add_allow_out_of_range_flag(CLI::App* sub, bool& allow) {
  sub->add_flag("--allow-out-of-range", allow,
                "Go on when a TF file's or given range leaves over 95 % of a field's values outside it (over 5 % "
                "warns)");
}

}  // namespace tfm::cli
