// `tfmatch solvers`: runs every voxel solver on one problem (given fields, or the built-in
// synthetic pair at the paper's 1.76 M-voxel Necker grid) and prints a table like the paper's
// Table 1, as text and/or JSON.
#include <iostream>
#include <map>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "solver_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/report/result_json.h"
#include "tfmatch/solvers/solver_comparison.h"

namespace tfm::cli {
namespace {

struct SolversArgs {
  InputArgs input;
  bool synthetic = false;
  std::string size = "250x352x20";  // the Necker et al. grid of the paper: 1.76 M voxels
  std::vector<std::string> solvers;
  double ridge = 0.0, smooth = 0.0;
  std::string json;
  std::map<std::string, std::string> extra;  // solver options (solver_options.h)
};

int run(const SolversArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  SolverSettings settings;
  settings.solve.ridge = a.ridge;
  settings.solve.smooth = a.smooth;
  settings.extra = a.extra;
  // Unknown solvers and bad or misapplied solver flags fail before loading, as usage errors.
  check_usage([&] { plan_comparison(settings, a.solvers); });
  FilePlan()
      .input_spec(a.input.ref, "--ref")
      .input_spec(a.input.field, "--field")
      .input_spec(a.input.ref_tf, "--ref-tf")
      .output(json.file(), "--json")
      .check();
  LoadedInputs in;
  if (a.synthetic) {
    if (!a.input.ref.empty() || !a.input.field.empty() || !a.input.ref_tf.empty())
      throw std::runtime_error("--synthetic replaces --ref, --ref-tf and --field; give either");
    reject_input_flags(a.input, "--synthetic replaces them");
    const auto d = *parse_grid_size(a.size);  // checked as the command line was
    in.ref = synthetic_reference(d[0], d[1], d[2]);
    in.field = synthetic_remapped(in.ref);
    in.request.ref = &in.ref;
    in.request.field = &in.field;
    in.request.ref_tf = demo_transfer_function(64);
    in.request.tf_size = a.input.tf_size;
  } else {
    if (a.input.ref.empty() || a.input.field.empty() || a.input.ref_tf.empty())
      throw std::runtime_error("give --ref, --ref-tf and --field, or --synthetic");
    load_inputs(a.input, in);
  }
  in.request.settings = settings;
  auto ctx = make_context();
  // One line per finished solver on stderr: a full comparison on large data takes minutes.
  const bool progress = !globals().quiet;
  const ComparisonResult result =
      compare_solvers(*ctx, in.request, a.solvers, [progress](const ComparisonRow& row, size_t i, size_t count) {
        if (!progress) return;
        std::cerr << "  [" << i << "/" << count << "] " << row.solver
                  << (row.error.empty() ? ": " + std::to_string(int(row.total_ms)) + " ms" : ": failed") << "\n";
      });
  json.write(to_json(result));
  if (!globals().quiet) {
    if (a.synthetic) std::cout << "synthetic pair " << a.size << " (tfmatch demo's fields)\n";
    result.print_table(std::cout);
    if (!json.file().empty()) std::cout << "wrote " << a.json << "\n";
  }
  return 0;
}

CommandRegistration reg(15, [](CLI::App& app) {
  auto args = std::make_shared<SolversArgs>();
  auto* sub = app.add_subcommand(
      "solvers", "Run every solver on one problem and compare time, iterations, voxel loss and the box constraints");
  add_input_options(sub, args->input, false);
  sub->add_flag("--synthetic", args->synthetic, "Use the built-in synthetic pair instead of --ref/--ref-tf/--field");
  sub->add_option("--size", args->size, "--synthetic: grid size XxYxZ")->check(grid_size_check())->capture_default_str();
  sub->add_option("--solvers", args->solvers, "Solvers to run, comma-separated (default: every voxel solver; name the "
                  "image-based diffdvr to include it — it takes minutes on large fields; qp always runs as the reference)")
      ->delimiter(',');
  sub->add_option("--ridge", args->ridge, "Tikhonov weight, relative to the mean diagonal of M")
      ->check(non_negative());
  sub->add_option("--smooth", args->smooth, "First-difference smoothness weight, relative to the mean diagonal of M, at most 1e9")
      ->check(non_negative());
  add_json_option(sub, args->json, "the comparison");
  add_solver_options(sub, args->extra);
  sub->footer(solver_descriptions());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
