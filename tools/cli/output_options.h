// The output conventions every subcommand shares: `--json FILE` ('-' for stdout) with one writer,
// and output names whose extension must name the format written (checked while parsing, before
// any work).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "tfmatch/io/json.h"

namespace tfm::cli {

// An output format: the extensions a file of it may end in (lower case, compared without case;
// the first is the one suggested) and what it is, for messages ("PNG image").
struct OutputFormat {
  std::vector<std::string> extensions;
  std::string name;
};
const OutputFormat& png_format();
const OutputFormat& json_format();
const OutputFormat& transfer_function_format();  // .json, .xml, .paraview.json (tf_formats.h)
const OutputFormat& field_format();               // .vti, or float32 .raw
const OutputFormat& vti_format();

// Throws CLI::ValidationError "ROLE: 'PATH' would hold a FORMAT: name it .EXT" when `path` does not
// end in one of the format's extensions. An empty path (option not given) passes.
void check_output_format(const std::string& path, const OutputFormat& format, const std::string& role);
// True when the file name of `path` ends in `extension` (".vti"), compared without case as
// check_output_format compares: how a command that writes two formats picks one.
bool has_extension(const std::string& path, const std::string& extension);
// The same check as a CLI11 validator, for an option whose value is an output file ('-' passes
// when `allow_stdout`).
CLI::Validator output_format(const OutputFormat& format, bool allow_stdout = false);

// Adds `--json FILE` to `sub` ('-': JSON on stdout and no text there; a file must end in .json).
// `what` completes the help: "Also write WHAT as JSON ...".
CLI::Option* add_json_option(CLI::App* sub, std::string& target, const std::string& what);

// The one writer of --json. Constructed with the option's value before the command prints
// anything: for '-' it keeps stdout for the JSON and sends what the command prints there for people
// (tables, summaries) to /dev/null until it is destroyed, so stdout is one JSON document; stderr
// (progress, warnings, errors) is untouched. Throws std::runtime_error when stdout cannot be set aside.
// Where the run's time went so far (host/model/phase_timer.h), in milliseconds: one entry per phase
// ("startup_ms" ... "write_ms"), "total_ms" since the program started and "other_ms", the rest
// (parsing, host-side work between phases; negative only when phases ran side by side).
nlohmann::json timings_json();

// The device this run made its context on (make_context records it), for environment_json().
void record_run_device(const std::string& device, const std::string& driver);
// Where a run's figures come from, in every JSON object as `environment`: tfmatch's version,
// commit and build type, the CPU threads, and the device and driver when the run made a context
// (figures gathered from many machines then say which; docs/commands.md).
nlohmann::json environment_json();

class JsonOutput {
 public:
  explicit JsonOutput(std::string target);
  ~JsonOutput();
  JsonOutput(const JsonOutput&) = delete;
  JsonOutput& operator=(const JsonOutput&) = delete;

  bool wanted() const { return !target_.empty(); }
  bool to_stdout() const { return target_ == "-"; }
  // The file to declare to FilePlan: empty when there is none or the JSON goes to stdout.
  std::string file() const { return to_stdout() ? std::string() : target_; }
  // Writes `j` (indented, one trailing newline): to stdout, or atomically to the file (inside the
  // caller's OutputBatch, so it appears only when the whole run succeeds). Nothing when not wanted.
  void write(const nlohmann::json& j) const;

 private:
  std::string target_;
  int stdout_fd_ = -1;  // the real stdout while descriptor 1 points at /dev/null
};

}  // namespace tfm::cli
