// The `tfmatch` program: parses the command line and runs the chosen subcommand.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <iostream>
#include <memory>
#include <new>
#include <optional>
#include <regex>
#include <sstream>
#include <string_view>

#include "cli.h"
#include "output_options.h"
#include "tfmatch/model/cancellation.h"
#ifdef TFMATCH_HAVE_CUDA
#include "tfmatch/cuda/cuda_solver_registration.h"
#endif
#include "interrupts.h"
#include "tfmatch/model/memory_budget.h"
#ifdef TFMATCH_HAVE_MPI
#include "tfmatch/mpi/mpi_ranks.h"
#endif
#include "tfmatch/engine/vk_check.h"
#include "tfmatch/io/pipeline_cache_file.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/shell_words.h"
#include "tfmatch/shaders/shader_registry.h"
#include "tfmatch_version.h"  // generated in the build directory (top-level CMakeLists.txt)

namespace tfm::cli {

GlobalOptions& globals() {
  static GlobalOptions g;
  return g;
}

void print_note(const std::string& text, const std::string& prefix) {
  if (!globals().quiet) std::cerr << prefix << ": note: " << text << "\n";
}

void print_warning(const std::string& text) { std::cerr << "tfmatch: warning: " << text << "\n"; }

std::vector<std::pair<int, CommandSetup>>& registered_commands() {
  static std::vector<std::pair<int, CommandSetup>> list;
  return list;
}

CommandRegistration::CommandRegistration(int order, CommandSetup setup) {
  registered_commands().emplace_back(order, std::move(setup));
}

int& exit_code() {
  static int code = 0;
  return code;
}

// Set when a context reported validation messages: the run is then a failure (exit code 3),
// whatever the command returned.
static bool& validation_failed() {
  static bool failed = false;
  return failed;
}

std::string exit_code_help() {
  return "Exit codes:\n"
         "  0    done\n"
         "  1    error: the message names the file or option and what is wrong; nothing written\n"
         "  2    usage: unknown, missing or misapplied option or value (e.g. a solver flag of another solver,\n"
         "       an output name whose extension is not the format written)\n"
         "  3    the Vulkan validation layer reported a message (--validation; in selftest, one outside every\n"
         "       case: one while a case runs fails that case, exit 1)\n"
         "  4    Vulkan error: no usable device, or the driver failed\n"
         "  130  interrupted by SIGINT (Ctrl-C), 143 by SIGTERM: stopped within a second, nothing written\n"
         "       (tfmatch view ends this way normally: exit 0)\n";
}

void check_usage(const std::function<void()>& check) {
  try {
    check();
  } catch (const std::runtime_error& e) {
    throw CLI::ValidationError(e.what());
  }
}

void remove_options(CLI::App* sub, std::initializer_list<const char*> names) {
  for (const char* name : names)
    if (!sub->remove_option(sub->get_option(name))) throw std::logic_error(std::string("no option ") + name);
}

std::optional<std::array<uint64_t, 3>> parse_grid_size(const std::string& text) {
  static const std::regex size(R"(([0-9]{1,12})x([0-9]{1,12})x([0-9]{1,12}))");
  std::smatch m;
  if (!std::regex_match(text, m, size)) return std::nullopt;
  std::array<uint64_t, 3> d{std::stoull(m[1]), std::stoull(m[2]), std::stoull(m[3])};
  if (!d[0] || !d[1] || !d[2]) return std::nullopt;
  return d;
}

CLI::Validator grid_size_check() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        return parse_grid_size(text) ? "" : "expected a grid size XxYxZ of positive integers, got '" + text + "'";
      },
      "XxYxZ");
}

ContextOptions context_options(bool validation_when_installed) {
  ContextOptions options;
  std::string d = globals().device;
  const Ranks& ranks = *globals().ranks;
  if (ranks.size() > 1) {
    // Under MPI a list of devices is one per node-local rank (cycled); without --device each
    // rank takes the node's devices in turn.
    std::vector<std::string> list;
    for (std::stringstream ss(d); std::getline(ss, d, ',');) list.push_back(d);
    if (!list.empty()) {
      d = list[size_t(ranks.local_rank()) % list.size()];
    } else if (const size_t count = enumerate_devices().size(); count > 0) {
      d = std::to_string(size_t(ranks.local_rank()) % count);
    }
  }
  if (!d.empty()) {
    if (std::optional<uint32_t> index = parse_device_index(d, "--device")) options.device_index = index;
    else options.device_name = d;
  }
  if (globals().validation) {
    options.validation = true;
    options.require_validation = true;
  } else if (validation_when_installed) {
    options.validation = true;
  }
  return options;
}

std::shared_ptr<Context> make_context(bool validation_when_installed) {
  const ContextOptions options = context_options(validation_when_installed);
  std::unique_ptr<Context> created = Context::create(options);
  record_run_device(created->device_name(), created->driver_description());  // every JSON's `environment`
  // --validation fails without the layer; the variable leaves it on where installed (the tests
  // set it everywhere), so say when it asked for what this run does not have.
  if (const char* env = std::getenv("TFMATCH_VALIDATION");
      env && *env && std::string(env) != "0" && !created->validation_enabled())
    print_warning(std::string("TFMATCH_VALIDATION=") + env +
                  ", but the Khronos validation layer is not installed: this run is not validated "
                  "(apt-get install vulkan-validationlayers; --validation makes this an error)");
  // The pipelines of earlier runs on this device and build, so this one need not compile them.
  std::optional<std::filesystem::path> cache_file;
  std::vector<uint8_t> cached;
  if (const auto dir = pipeline_cache_directory()) {
    PhaseScope timing(Phase::Startup);
    cache_file = pipeline_cache_path(*dir, created->pipeline_cache_identity(), shaders_fingerprint());
    StoredPipelineCache stored = read_pipeline_cache(*cache_file);
    std::string note = stored.note;
    try {
      if (!stored.data.empty() && created->merge_pipeline_cache_data(stored.data, &note)) cached = std::move(stored.data);
      else if (!stored.data.empty()) note = "pipeline cache " + cache_file->string() + " ignored: " + note;
    } catch (const VulkanError& e) {
      note = "pipeline cache " + cache_file->string() + " ignored: the driver refused it (" + e.what() + ")";
    }
    if (!note.empty()) print_note(note);
  }
  return std::shared_ptr<Context>(created.release(), [cache_file, cached = std::move(cached)](Context* ctx) {
    auto messages = ctx->take_validation_messages();
    for (const std::string& m : messages) std::cerr << "tfmatch: Vulkan validation " << m << "\n";
    if (!messages.empty()) validation_failed() = true;
    // Stored only when this run added pipelines; a failure to store costs the next run time only.
    if (cache_file) {
      try {
        const std::vector<uint8_t> data = ctx->pipeline_cache_data();
        if (data != cached) {
          const std::string problem = write_pipeline_cache(*cache_file, data);
          if (!problem.empty()) print_note("pipeline cache not stored: " + problem);
        }
      } catch (const std::exception& e) {
        print_note(std::string("pipeline cache not stored: ") + e.what());
      }
    }
    delete ctx;
  });
}

StartingContext::StartingContext()
    : reservation_(std::make_unique<MemoryReservation>(kStartingContextBytes, "the Vulkan device starting")),
      started_(std::async(std::launch::async, [this] {
        const UntimedThread overlapped;  // counted as the wait in get()
        std::shared_ptr<Context> ctx = make_context();
        reservation_->release();  // in the process's resident memory now
        return ctx;
      })) {}

std::shared_ptr<Context> StartingContext::get() {
  if (!context_) {
    PhaseScope timing(Phase::Startup);
    context_ = started_.get();
  }
  return context_;
}

FieldRange parse_range(const std::string& text, const std::string& flag) {
  auto comma = text.find(',');
  FieldRange r;
  try {
    if (comma == std::string::npos) throw std::invalid_argument("no comma");
    size_t used = 0;
    r.lo = std::stod(text.substr(0, comma), &used);
    if (used != comma) throw std::invalid_argument("junk");
    std::string rest = text.substr(comma + 1);
    r.hi = std::stod(rest, &used);
    if (used != rest.size()) throw std::invalid_argument("junk");
  } catch (const std::exception&) {
    throw CLI::ValidationError(flag, "expected lo,hi (two numbers), got '" + text + "'");
  }
  try {
    check_range(r, flag);  // "inf", "nan", reversed, beyond float32
  } catch (const std::runtime_error& e) {
    throw CLI::ValidationError(e.what());
  }
  return r;
}

const CLI::Validator& positive_integer() {
  static const CLI::Validator validator(
      [](std::string& text) -> std::string {
        const bool digits = !text.empty() && text.size() < 20 && std::all_of(text.begin(), text.end(), ::isdigit);
        if (!digits || std::stoull(text) == 0) return "expected a positive integer, got '" + text + "'";
        return {};
      },
      "POSITIVE INTEGER");
  return validator;
}

namespace {

// A finite number >= 0 (or > 0 where `zero_allowed` is false).
CLI::Validator sign_check(bool zero_allowed, const char* description) {
  return CLI::Validator(
      [zero_allowed](std::string& text) -> std::string {
        double v = 0.0;
        const bool ok = CLI::detail::lexical_cast(text, v) && std::isfinite(v) && (zero_allowed ? v >= 0.0 : v > 0.0);
        if (!ok) return std::string("expected a number ") + (zero_allowed ? ">= 0" : "> 0") + ", got '" + text + "'";
        return {};
      },
      description);
}

// The type CLI11 gives an option ("FLOAT", "UINT", ...), without its validators' descriptions.
std::string base_type(const CLI::Option& option) {
  const std::string full = option.get_type_name();
  return full.substr(0, full.find(':'));
}

}  // namespace

const CLI::Validator& non_negative() {
  static const CLI::Validator validator = sign_check(true, "NONNEGATIVE");
  return validator;
}

const CLI::Validator& positive() {
  static const CLI::Validator validator = sign_check(false, "POSITIVE");
  return validator;
}

void require_numbers(CLI::App& app) {
  for (CLI::Option* option : app.get_options()) {
    const std::string type = base_type(*option);
    const bool is_float = type == "FLOAT", is_unsigned = type == "UINT", is_integer = is_unsigned || type == "INT";
    if (!is_float && !is_integer) continue;
    // With empty descriptions, so that --help and docs/commands.md read as before. Not a number at
    // all: ahead of the option's own checks (transform() puts a validator first; this one changes
    // nothing), whose range message would read "Value  not in range 1 to 16384" for ''. A minus
    // sign: after them, so that a range says what it allows.
    option->transform(CLI::Validator(
        [is_float](std::string& text) -> std::string {
          double v = 0.0;
          if (text.find_first_not_of(" \t") == std::string::npos ||
              (is_float && CLI::detail::lexical_cast(text, v) && std::isnan(v)))
            return "expected a number, got '" + text + "'";
          // No option takes an infinity (limits are numbers, angles finite): a usage error as NaN
          // is, not a failure of the run after the inputs were read.
          if (is_float && CLI::detail::lexical_cast(text, v) && std::isinf(v))
            return "expected a finite number, got '" + text + "'";
          return {};
        },
        ""));
    if (is_unsigned)
      option->check(CLI::Validator(
          [](std::string& text) -> std::string {
            const size_t first = text.find_first_not_of(" \t");
            if (first != std::string::npos && text[first] == '-') return "expected a number >= 0, got '" + text + "'";
            return {};
          },
          ""));
  }
  for (CLI::App* sub : app.get_subcommands({})) require_numbers(*sub);
}

std::string version_text() {
  std::ostringstream os;
  os << "tfmatch " << TFMATCH_VERSION << "\n"
     << "commit: " << TFMATCH_GIT_COMMIT << "\n"
     << "build type: " << TFMATCH_BUILD_TYPE << "\n"
     << "Vulkan headers: " << VK_API_VERSION_MAJOR(VK_HEADER_VERSION_COMPLETE) << "."
     << VK_API_VERSION_MINOR(VK_HEADER_VERSION_COMPLETE) << "." << VK_HEADER_VERSION << "\n"
     << "compiler: " << TFMATCH_COMPILER;
  return os.str();
}

std::string version_line() { return std::string("tfmatch ") + TFMATCH_VERSION + " (commit " + TFMATCH_GIT_COMMIT + ")"; }

// argv as a shell would need it typed (shell_word).
static std::string quoted_command_line(int argc, char** argv) {
  std::string out;
  for (int i = 0; i < argc; ++i) out += (i ? " " : "") + shell_word(argv[i]);
  return out;
}

}  // namespace tfm::cli

namespace tfm::cli {

// What a failed run prints after "tfmatch: " and its exit code (exit_code_help()).
Failure describe_failure(std::exception_ptr failure) {
  try {
    std::rethrow_exception(failure);
  } catch (const tfm::Cancelled& c) {
    // Unwinding has removed the temporary files and staged outputs: nothing was written.
    return {"interrupted (" + std::string(signal_name(c.signal())) + "): stopped; no output written", 128 + c.signal(),
            true};
  } catch (const tfm::RankFailure& e) {
    return {e.what(), e.exit_code()};
  } catch (const CLI::ParseError& e) {  // a usage error on some ranks of a job only (main())
    return {std::string("error: ") + e.what(), kExitUsage};
  } catch (const tfm::VulkanError& e) {
    return {std::string("Vulkan error: ") + e.what(), kExitVulkan};
  } catch (const tfm::DeviceChoiceError& e) {  // no usable device: as a driver that fails
    return {std::string("error: ") + e.what(), kExitVulkan};
  } catch (const std::bad_alloc&) {
    // Allocations an input decides are checked against the budget first; this is what slipped by.
    return {"error: out of memory (the memory budget is " + tfm::format_bytes(tfm::memory_budget().bytes) +
                "; see --max-memory)",
            kExitError};
  } catch (const std::exception& e) {
    return {std::string("error: ") + e.what(), kExitError};
  } catch (...) {
    return {"error: unknown failure", kExitError};
  }
}

}  // namespace tfm::cli

int main(int argc, char** argv) {
  using namespace tfm::cli;
#ifdef TFMATCH_HAVE_CUDA
  tfm::register_cuda_solvers();  // before the options are made from the solver registry
#endif
  // Library messages name parameters; this program's users read the flags they type.
  tfm::set_parameter_style([](std::string_view name) { return "--" + std::string(name); });
  install_interrupt_handlers();
  globals().command_line = quoted_command_line(argc, argv);
#ifdef TFMATCH_HAVE_MPI
  // Started by mpirun/srun: this process is one rank of a job (docs/mpi.md). Ranks other than 0
  // print nothing: rank 0 reports for the job, the failing rank's message included.
  std::unique_ptr<tfm::MpiRanks> mpi;
  if (tfm::MpiRanks::launched()) {
    try {
      mpi = std::make_unique<tfm::MpiRanks>(argc, argv, [](std::exception_ptr e) {
        const Failure f = describe_failure(e);
        return tfm::MpiRanks::Failure{f.message, f.exit_code};
      });
    } catch (const std::exception& e) {
      std::cerr << "tfmatch: error: " << e.what() << "\n";
      return kExitError;
    }
    globals().ranks = mpi.get();
    if (mpi->rank() != 0) {
      std::fflush(nullptr);
      if (!std::freopen("/dev/null", "w", stdout) || !std::freopen("/dev/null", "w", stderr)) return kExitError;
      tfm::set_progress_enabled(false);
    }
  }
#endif
  CLI::App app{"tfmatch: optimize a transfer function so a second field's volume renderings match a reference's"};
  app.require_subcommand(1);
  // Global flags are accepted after the subcommand too (`tfmatch info big.nrrd --max-memory 1G`).
  app.fallthrough();
  app.set_help_all_flag("--help-all", "Print help for every subcommand");
  app.set_version_flag("--version", version_text(), "Print the version, git commit, build type, Vulkan headers and compiler");
  app.add_option("--device", globals().device, "Vulkan device: index or name substring (env TFMATCH_DEVICE)");
  app.add_flag("--validation", globals().validation, "Enable the Khronos validation layer (env TFMATCH_VALIDATION=1)");
  app.add_flag_callback(
      "-q,--quiet",
      [] {
        globals().quiet = true;
        tfm::set_progress_enabled(false);  // before any command runs, whichever shows progress
      },
      "Print only errors and warnings (no summaries, notes or progress)");
  app.footer(exit_code_help());
  // The budget's source as messages quote it: the flag, or the environment when it is not given.
  bool max_memory_flag = false;
  for (int i = 1; i < argc; ++i)
    max_memory_flag |= std::string_view(argv[i]) == "--max-memory" || std::string_view(argv[i]).starts_with("--max-memory=");
  app.add_option_function<std::string>(
         "--max-memory",
         [max_memory_flag](const std::string& text) {
           const std::string source = max_memory_flag ? "--max-memory " + text : "TFMATCH_MAX_MEMORY=" + text;
           const auto bytes = tfm::parse_byte_size(text);
           if (!bytes)
             throw CLI::ValidationError(max_memory_flag ? "--max-memory" : "TFMATCH_MAX_MEMORY",
                                        "expected a size such as 512M, 2G or 1.5GiB, got '" + text + "'");
           // Below what tfmatch holds before reading anything every command would fail, each
           // blaming whatever it asked for first.
           if (*bytes < tfm::kMinMemoryBudget)
             throw CLI::ValidationError(max_memory_flag ? "--max-memory" : "TFMATCH_MAX_MEMORY",
                                        source + " is below " + tfm::format_bytes(tfm::kMinMemoryBudget) +
                                            ": tfmatch holds about 12 MiB before reading anything, and a "
                                            "Vulkan device 60 MiB or more");
           tfm::set_memory_budget(*bytes, source);
         },
         "Most memory tfmatch may hold, e.g. 2G or 512M (env TFMATCH_MAX_MEMORY; default: the memory available at "
         "start). Inputs that would need more fail before loading, naming the file and the size")
      ->envname("TFMATCH_MAX_MEMORY");
  auto& commands = registered_commands();
  std::sort(commands.begin(), commands.end(), [](auto& a, auto& b) { return a.first < b.first; });
  for (auto& [order, setup] : commands) setup(app);
  require_numbers(app);
  // Under MPI only the streamed optimize and correlate are split over ranks; every other command
  // runs in one process (docs/mpi.md).
  if (globals().ranks->size() > 1)
    for (CLI::App* sub : app.get_subcommands({}))
      if (sub->get_name() != "optimize" && sub->get_name() != "correlate")
        sub->preparse_callback([name = sub->get_name()](size_t) {
          throw CLI::ValidationError(name, "runs in one process: under MPI (" + std::to_string(globals().ranks->size()) +
                                               " ranks) only `optimize --stream on` and `correlate` are split over ranks (docs/mpi.md)");
        });
  std::exception_ptr failure;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are "errors" of CLI11 that exit 0; every other one is a usage error.
    // Under MPI a usage error can be one rank's alone (its environment's TFMATCH_MAX_MEMORY, a
    // pattern that matches no file there, a --marker outside the grid that rank reads): the ranks
    // agree on it below, as on any failure, so none is left waiting in a collective.
    if (e.get_exit_code() == 0 || globals().ranks->size() == 1) return app.exit(e) == 0 ? kExitOk : kExitUsage;
    failure = std::current_exception();
  } catch (...) {
    failure = std::current_exception();
  }
  tfm::Ranks& ranks = *globals().ranks;
  if (&ranks != &tfm::single_rank()) {
    // A job's ranks end together: a failure on any rank is every rank's (ranks.h), and only rank
    // 0 reports it.
    try {
      if (failure) {
        try {
          std::rethrow_exception(failure);
        } catch (const tfm::RankFailure&) {
          throw;  // already agreed: no further collective
        } catch (...) {
          ranks.agree(failure);
        }
      } else {
        ranks.agree(nullptr);
      }
    } catch (const tfm::RankFailure& f) {
      if (ranks.rank() == 0) std::cerr << "tfmatch: " << f.what() << "\n";
      note_ending_reported();  // the MPI teardown may wait for a rank still stopping
      return f.exit_code();
    }
  } else if (failure) {
    const Failure f = describe_failure(failure);
    std::cerr << (f.interrupted ? "\n" : "") << "tfmatch: " << f.message << "\n";
    note_ending_reported();
    return f.exit_code;
  }
  if (validation_failed()) return kExitValidation;
  return exit_code();
}
