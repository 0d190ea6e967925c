// Subcommand registry of the `tfmatch` program and helpers shared by subcommands.
#pragma once

#include <functional>
#include <initializer_list>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "tfmatch/engine/context.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/ranks.h"

namespace tfm::cli {

// Options every subcommand that computes shares (device selection, validation).
struct GlobalOptions {
  std::string device;        // index or name substring
  bool validation = false;
  bool quiet = false;
  std::string command_line;  // as typed, shell-quoted where needed: what a report records
  // The ranks of an MPI job when a launcher started this process (host/mpi), else this process
  // alone (docs/mpi.md). Only rank 0 prints and writes.
  Ranks* ranks = &single_rank();
};
GlobalOptions& globals();

// Prints "<prefix>: note: <text>" on stderr unless -q: a note says what tfmatch chose or did
// (a cache ignored, a file loaded whole, a TF clamped), never that a result may be wrong; a
// warning does that, and -q keeps warnings.
void print_note(const std::string& text, const std::string& prefix = "tfmatch");
// Prints "tfmatch: warning: <text>" on stderr, with -q too.
void print_warning(const std::string& text);

// A subcommand adds itself to the app; its callback sets the exit code through `exit_code()`.
using CommandSetup = std::function<void(CLI::App& app)>;
struct CommandRegistration {
  CommandRegistration(int order, CommandSetup setup);
};
std::vector<std::pair<int, CommandSetup>>& registered_commands();
int& exit_code();

// The exit codes of `tfmatch`, listed in `tfmatch --help` by exit_code_help().
enum ExitCode : int {
  kExitOk = 0,
  kExitError = 1,       // the run failed: a message names the file or option and what is wrong
  kExitUsage = 2,       // the command line is wrong: unknown, missing or misapplied option or value
  kExitValidation = 3,  // the Khronos validation layer reported a message
  kExitVulkan = 4,      // no usable Vulkan device, or the driver failed
  // 128 + signal (130 SIGINT, 143 SIGTERM): interrupted; nothing written
};
std::string exit_code_help();

// What a failed run prints after "tfmatch: " and the exit code it means (main's handler, and
// what a failing MPI rank tells the others).
struct Failure {
  std::string message;
  int exit_code = kExitError;
  bool interrupted = false;  // printed on a line of its own
};
Failure describe_failure(std::exception_ptr failure);

// Runs `check` (a check of flag values made outside CLI11, such as the solver-flag checks of
// host/solvers) and turns what it throws into a usage error (exit code 2).
void check_usage(const std::function<void()>& check);

// Removes options that a shared add_*_options() gave `sub` and that it sets by its own means (a
// benchmark's --images sizes, --tf-sizes), so that they are refused as unknown rather than
// accepted and ignored.
void remove_options(CLI::App* sub, std::initializer_list<const char*> names);

// A grid size "XxYxZ" (three positive integers of at most 12 digits, nothing else): parsed, or
// std::nullopt. grid_size_check() is it as a CLI11 check, so that every size of a list is a usage
// error before any work (bench ran the sizes before a bad one, and read "8x8x8,16x16x16" as 8x8x8).
std::optional<std::array<uint64_t, 3>> parse_grid_size(const std::string& text);
CLI::Validator grid_size_check();

// The device choice and validation of the global options (--device, --validation; under MPI the
// node-local rank's device).
ContextOptions context_options(bool validation_when_installed = false);

// Creates the Vulkan context from the global options. When validation is on, the messages it
// collected are printed to stderr as the context is released, and the exit code becomes 3.
// `validation_when_installed` turns the layer on without --validation where it is installed.
std::shared_ptr<Context> make_context(bool validation_when_installed = false);

// What making a context adds to the process's resident memory, about: lavapipe 62 MiB (81 MiB
// with the validation layer), measured from before make_context() to after it.
inline constexpr uint64_t kStartingContextBytes = 64ull << 20;

// make_context() on a helper thread, begun at construction, so that a command reads its inputs
// while the driver creates the instance and device (each takes 0.1 s or more on a GPU driver,
// about as long as reading a large pair of fields from the page cache). get() waits for it
// (counted as start-up time, the part the reading did not hide) and rethrows what it threw; the
// destructor waits too, so an input error reported first still finds the device released.
// Until the device exists, memory checks made meanwhile count kStartingContextBytes as in use.
class StartingContext {
 public:
  StartingContext();
  std::shared_ptr<Context> get();

 private:
  std::unique_ptr<MemoryReservation> reservation_;  // before started_, which refers to it
  std::future<std::shared_ptr<Context>> started_;
  std::shared_ptr<Context> context_;
};

// `tfmatch --version`: version, git commit, build type, Vulkan headers, compiler (one per line).
std::string version_text();
// "tfmatch 0.3.0 (commit abc123)": one line for reports.
std::string version_line();

// Parses "lo,hi"; throws CLI::ValidationError with a clear message (check_range's for a range
// that is not finite, reversed, or beyond float32).
FieldRange parse_range(const std::string& text, const std::string& flag);

// Accepts a positive integer only: CLI11 alone reads "-64" into an unsigned as 2^64 - 64.
const CLI::Validator& positive_integer();

// A finite number >= 0 / > 0, with the help text of CLI11's NonNegativeNumber / PositiveNumber
// ("NONNEGATIVE", "POSITIVE") but a message that says what was expected instead of printing
// DBL_MAX in full ("--ridge: expected a number >= 0, got '-1'").
const CLI::Validator& non_negative();
const CLI::Validator& positive();

// Every numeric option of `app` and its subcommands refuses an empty value, NaN and, where it is
// unsigned, a minus sign — each a usage error naming the option. CLI11 alone reads "" as 0, lets
// NaN through every range check (NaN < lo and NaN > hi are both false) and wraps "-1" to 2^64 - 1.
void require_numbers(CLI::App& app);

}  // namespace tfm::cli
