// The one interface of every solver: what it is (name, summary, the constraints it honours),
// its typed and documented options, and solve(); the explicit registry of all solvers; and the
// central parsing of option values from text into typed, range-checked values.
//
// Adding a solver touches two files: a new solver_<name>.cpp that defines a Solver subclass and
// a factory `std::unique_ptr<Solver> make_<name>_solver()`, and solver_registry.cpp, which
// declares the factory and calls it in make_solvers(). The command line's flags and help follow
// from options(); tests/host/solvers/test_solver_registry.cpp lists the expected names.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/solvers/details.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {

class Solver;

struct PhaseTime {
  std::string name;
  double wall_ms = 0.0;
  double gpu_ms = -1.0;  // -1: not measured on the GPU
};

// Everything a solver sees: both fields on the device, their mappings, the reference TF.
struct VoxelProblem {
  Context& ctx;
  const Volume& ref_volume;      // host copies (dims, spacing; image-based solvers render them)
  const Volume& opt_volume;
  const DeviceField& ref;
  const DeviceField& opt;
  FieldMapping ref_map;
  FieldMapping opt_map;          // tf_size = N of the TF being optimized
  const TransferFunction& ref_tf;
  const Buffer& ref_tf_buffer;
  TransferFunction initial;      // the reference TF resampled to N (starting point)
  // M, S^T b and b^T b of (ref, opt) for opt_map, once a solver or run_optimize has assembled
  // them (assembled_system() in solver_support.h): the voxel loss of any TF follows from them.
  std::optional<NormalEquations> system = std::nullopt;
  // When set (the reference TF has another size than N): the second field mapped onto the
  // reference TF's entries; the assembly then also sums the loss before optimization
  // (NormalEquations::before) in the same pass.
  std::optional<FieldMapping> before_map = std::nullopt;
};

struct SolverOutput {
  TransferFunction tf;                // in [0,1]
  std::vector<PhaseTime> phases;
  std::vector<std::string> warnings;
  Details details;                    // solver-specific numbers (cond, iterations, ...)
};

// What a caller gives a solver, before parsing.
struct SolverSettings {
  SolveOptions solve;                 // regularization and factorization (--ridge, --smooth, ...)
  // Values of the solver's options by flag name without dashes ("iterations" -> "300"), as
  // typed on the command line. Each must be an option of the chosen solver (Solver::options());
  // options not given take their defaults.
  std::map<std::string, std::string> extra;
  // The optical model and camera of the renderings (image-based solvers render with these, so
  // the images optimized are the images shown).
  RenderSettings render;
};

// ---- options ----------------------------------------------------------------------------------

enum class OptionType {
  Integer,  // a whole number >= 0 (counts, seeds), in [integer_min, integer_max]
  Number,   // a finite number in `range`
  Choice,   // one of `choices`
  Text,     // any text
  Flag,     // on or off; given without a value on the command line
};

// Bounds of a Number option; an open bound is excluded.
struct NumberRange {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_open = false;
  bool max_open = false;
};

// How an Integer option reads `text`: digits, or a number with an exact whole value ("1e3",
// "+5", "5.0"); false when it is none (or past 2^64 - 1). Callers that bound an option further
// (the viewer) read it the same way, so that no spelling slips past their bound.
bool parse_option_integer(const std::string& text, uint64_t& out);

// A typed option value: none, flag, integer, number, or text (Choice and Text).
using OptionValue = std::variant<std::monostate, bool, uint64_t, double, std::string>;

// One option of a solver, declared once: the command line's flag and help, the central parser
// and the solver's typed reads all come from this.
struct SolverOption {
  std::string name;               // flag without dashes: "max-iterations"
  OptionType type = OptionType::Number;
  // Used when the option is not given; monostate: the solver picks (default_help says how).
  OptionValue default_value;
  std::string help;               // what it does, one line, without range or default
  std::string default_help;       // replaces the default in help text when not empty
  uint64_t integer_min = 0, integer_max = std::numeric_limits<uint64_t>::max();
  NumberRange range;
  std::vector<std::string> choices;

  static SolverOption integer(std::string name, uint64_t default_value, uint64_t min, uint64_t max, std::string help);
  static SolverOption number(std::string name, double default_value, NumberRange range, std::string help);
  static SolverOption choice(std::string name, std::string default_value, std::vector<std::string> choices,
                             std::string help);
  static SolverOption text(std::string name, std::string default_value, std::string help);
  static SolverOption flag(std::string name, std::string help);

  // The values it accepts, e.g. "an integer in [1, 1000]", "a number in (0, 1)", "l2 or l1".
  std::string describe_values() const;
  // Its default as help shows it ("1e-06", "l2", ...), or default_help; empty when none.
  std::string describe_default() const;
  // Parses `text` as this option's value. Throws std::runtime_error naming the flag and
  // `solver` when it is not a value of this option (wrong type, out of range, not a choice).
  OptionValue parse(const std::string& text, std::string_view solver) const;
};

// The parsed options of one solve, with the shared settings.
class SolverArgs {
 public:
  SolveOptions solve;
  RenderSettings render;

  // Typed values of declared options. Throw std::logic_error for a name the solver did not
  // declare with that type, or an option without a value (no default and not given).
  uint64_t integer(std::string_view name) const;
  double number(std::string_view name) const;
  const std::string& text(std::string_view name) const;  // Choice and Text options
  bool flag(std::string_view name) const;
  // True when the value was given rather than defaulted.
  bool given(std::string_view name) const;
  // True when the option has a value (given, or a default).
  bool has(std::string_view name) const;

  const std::string& solver() const { return solver_; }

 private:
  friend SolverArgs parse_solver_args(const Solver& solver, const SolverSettings& settings);
  struct Entry {
    OptionType type;
    OptionValue value;
    bool given = false;
  };
  const Entry& entry(std::string_view name, OptionType type) const;
  std::string solver_;
  std::map<std::string, Entry, std::less<>> values_;
};

// ---- solvers ----------------------------------------------------------------------------------

// How a solver's result satisfies the box 0 <= x <= 1 of TF entries.
enum class BoxHandling {
  Clamped,    // the unconstrained minimizer, clamped afterwards
  Projected,  // every iterate projected to the box
  Enforced,   // the exact box-constrained minimizer
};
const char* box_handling_name(BoxHandling box);  // "clamped", "projected", "enforced"

struct SolverConstraints {
  BoxHandling box = BoxHandling::Clamped;
  bool ridge = true;    // honours SolveOptions::ridge (--ridge)
  bool smooth = true;   // honours SolveOptions::smooth (--smooth)
  bool factorization = false;  // honours SolveOptions::factorization (--factorization): solves M directly
};

class Solver {
 public:
  virtual ~Solver() = default;
  virtual std::string_view name() const = 0;     // "cgls"
  virtual std::string_view summary() const = 0;  // one line for help
  virtual SolverConstraints constraints() const = 0;
  // Optimizes renderings rather than voxel colours (left out of the default comparison).
  virtual bool image_based() const { return false; }
  virtual std::vector<SolverOption> options() const { return {}; }
  // Why this solver cannot run in this process (the CUDA solvers without a CUDA device or their
  // plugin), led by its name; empty when it can. May load what it needs to find out.
  virtual std::string unavailable() const { return {}; }
  // Solves `problem` with `args` from parse_solver_args(*this, ...). Throws std::runtime_error
  // for an unusable problem (no voxel with data, ...), VulkanError for device failures.
  virtual SolverOutput solve(VoxelProblem& problem, const SolverArgs& args) const = 0;
};

// Every solver, in name order, built on first use by make_solvers() (solver_registry.cpp), with
// those of optional components added before that (add_solvers).
const std::vector<std::unique_ptr<Solver>>& solvers();
// Adds the solvers `make` returns to the registry when it is built: how an optional component
// (the CUDA solvers, host/solvers/cuda) joins without tfmatch::tfmatch linking it. Throws
// std::logic_error once the registry has been built (call it first, as main() does).
void add_solvers(std::function<std::vector<std::unique_ptr<Solver>>()> make);
// The solver named `name`, or nullptr.
const Solver* find_solver(std::string_view name);
// The solver named `name`; throws std::runtime_error listing the available ones when unknown.
const Solver& require_solver(std::string_view name);
std::vector<std::string> solver_names();
// The solvers that declare an option named `option`, in registry order.
std::vector<const Solver*> solvers_with_option(std::string_view option);

// Throws std::runtime_error "--lr applies to solvers diffdvr, gradient-descent, not to
// normal-equations" for a flag in settings.extra that none of the `chosen` solvers declares, and
// for a SolveOptions value given (not its default: --ridge, --smooth, --factorization) that none
// of them honours (SolverConstraints); "unknown solver option --X" for a flag no solver declares.
void check_options_apply(const SolverSettings& settings, const std::vector<std::string>& chosen);

// Parses settings.extra for `solver`: every option it declares gets its given value (checked) or
// its default. Throws std::runtime_error naming the flag and the solver for a bad value, and for
// a flag the solver does not have ("--lr applies to solvers gradient-descent, diffdvr, not to
// normal-equations"; "unknown solver option --x" when no solver has it).
SolverArgs parse_solver_args(const Solver& solver, const SolverSettings& settings);

// require_solver(name).solve(problem, parse_solver_args(...)).
SolverOutput run_solver(std::string_view name, VoxelProblem& problem, const SolverSettings& settings);

}  // namespace tfm
