// The input flags of every subcommand that reads fields: how to read them (raw-file layout;
// --var, --time, --member selecting a NetCDF/GRIB field, overridden per file by FILE:VAR,...), and
// the flags of the subcommands that fit a TF (--ref, --ref-tf, --field, ranges, --tf-size) with
// their loading into an OptimizeRequest.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "tfmatch/io/json.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/solvers/optimize.h"

namespace tfm::cli {

// How every field of a command is read: raw-file layout and the field selectors.
struct VolumeFlags {
  std::vector<uint64_t> dims;
  std::string type;
  bool big_endian = false;
  std::string var;
  std::optional<uint64_t> time, member;
  // The options for reading `inputs` (the command's FILE[:SELECTION] specs). Throws
  // CLI::ValidationError for an unknown --type, and when --dims, --type or
  // --big-endian is given but none of `inputs` is a file they describe (raw; .dat for the byte
  // order): they would be ignored.
  VolumeOptions options(const std::vector<std::string>& inputs) const;
  bool selects() const { return !var.empty() || time || member; }  // --var, --time or --member given
};
// Which selectors a command takes: `correlate` reads the member axis whole, so it has no --member.
enum class FieldSelectors { VarTimeMember, VarTime };
// Adds --dims, --type, --big-endian (group "Raw volumes") and the selectors (group "Field selection").
void add_volume_flags(CLI::App* sub, VolumeFlags& flags, FieldSelectors selectors = FieldSelectors::VarTimeMember);

struct InputArgs {
  std::string ref, ref_tf, field;
  uint32_t tf_size = 64;
  std::string ref_range, field_range;
  bool allow_out_of_range = false;
  VolumeFlags volume;
};

// Adds the flags to `sub`; `required` makes --ref, --ref-tf and --field required.
void add_input_options(CLI::App* sub, InputArgs& args, bool required);

// Throws CLI::ValidationError naming the first flag given that says how to read or map the input
// files (--ref-range, --field-range, --allow-out-of-range, the raw-file layout and the field
// selectors) when a command runs without them, `instead` saying why (its built-in pair replaces
// them): such flags would be ignored.
void reject_input_flags(const InputArgs& args, const std::string& instead);

// The loaded inputs: volumes (owned here, the request points at them) and the request.
struct LoadedInputs {
  Volume ref, field;
  OptimizeRequest request;
};
// Loads the volumes and the reference TF (printing TF reader notes to stderr) and fills the
// request's inputs, ranges and TF size. Throws std::runtime_error naming a bad file or flag.
void load_inputs(const InputArgs& args, LoadedInputs& out);
// load_inputs() without the volumes: the reference TF, the ranges, the TF size and
// --allow-out-of-range into `out` (a streamed run reads the volumes slab by slab).
void load_tf_and_ranges(const InputArgs& args, FitSettings& out);

// The flags as JSON with absolute paths (a report's inputs.json, which `tfmatch view --report`
// reopens), and back; relative paths in the JSON are taken relative to `base`.
nlohmann::json input_args_json(const InputArgs& args);
InputArgs input_args_from_json(const nlohmann::json& j, const std::filesystem::path& base);

// The fields that several --field values name, in order: each as given; a selection range
// ",time=A..B" or ",member=A..B" (inclusive) as one field per index; a path with *, ? or [...] that
// names no file as the files it matches, in name order (glob(3)), each with the spec's selection.
// Throws CLI::ValidationError naming `flag` for a bad range, two ranges in one spec, or a pattern
// that matches nothing.
std::vector<std::string> expand_field_specs(const std::vector<std::string>& specs, const std::string& flag);

// --allow-out-of-range, for the commands that take ranges (field_mapping.h check_range_coverage).
void add_allow_out_of_range_flag(CLI::App* sub, bool& allow);

}  // namespace tfm::cli
