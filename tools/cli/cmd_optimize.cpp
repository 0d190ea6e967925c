// `tfmatch optimize`: fit a TF for a second field to a reference field and its TF.
#include <fstream>
#include <iostream>
#include <map>

#include "atomic_file.h"
#include "cli.h"
#include "input_options.h"
#include "optimize.h"
#include "progress.h"
#include "render_options.h"
#include "report.h"
#include "loss_plot.h"
#include "result_json.h"
#include "solver_options.h"
#include "tf_formats.h"
#include "volume.h"

namespace tfm::cli {
namespace {

struct OptimizeArgs {
  InputArgs in;                               // --ref, --ref-tf, --field, ranges, selectors, --tf-size
  std::string out, json;
  std::string solver = "normal-equations";
  double ridge = 0.0, smooth = 0.0;
  std::string factorization = "auto";
  std::map<std::string, std::string> extra;  // solver options (solver_options.h), checked by the solver
  std::string report;                         // report directory (renderings, metrics, index.html)
  RenderSettings render;
};

int run(const OptimizeArgs& a) {
  SolverSettings settings;
  settings.render = a.render;  // image-based solvers render as the report does
  settings.solve.ridge = a.ridge;
  settings.solve.smooth = a.smooth;
  settings.extra = a.extra;
  settings.solve.factorization = a.factorization == "ldlt" ? Factorization::LDLT
                                 : a.factorization == "qr" ? Factorization::QR
                                                           : Factorization::Auto;
  parse_solver_args(require_solver(a.solver), settings);  // bad solver flags fail before loading
  if (!a.report.empty()) validate(a.render);  // fail before the solve, not after
  LoadedInputs loaded;
  load_inputs(a.in, loaded);
  const Volume& ref = loaded.ref;
  const Volume& field = loaded.field;
  OptimizeRequest& req = loaded.request;
  req.solver = a.solver;
  req.settings = settings;
  auto ctx = make_context();
  req.voxel_mae = !a.json.empty() || !a.report.empty();  // both show the mean absolute error
  OptimizeResult result = run_optimize(*ctx, req);
  write_transfer_function(a.out, result.tf);
  if (!a.json.empty()) write_file_atomically(a.json, to_json(result).dump(2) + "\n");
  if (!globals().quiet) {
    result.print_summary(std::cout);
    std::cout << "  wrote " << a.out << (a.json.empty() ? "" : " and " + a.json) << "\n";
  }
  if (!a.report.empty()) {
    set_progress_enabled(!globals().quiet);
    ReportInputs inputs{ref, field, req.ref_tf, result, a.render};
    inputs.extra_figures = solver_report_figures(result, a.render.width);  // diffdvr: loss curve
    inputs.title = "tfmatch: " + field.name + " matched to " + ref.name;
    ReportSummary summary = write_report(*ctx, inputs, a.report);
    if (!globals().quiet)
      std::cout << "  images vs reference: reference TF " << summary.before.to_string() << "\n"
                << "                       optimized TF " << summary.after.to_string() << "\n"
                << "  report: " << summary.index.string() << "\n";
  }
  return 0;
}

CommandRegistration reg(10, [](CLI::App& app) {
  auto args = std::make_shared<OptimizeArgs>();
  auto* sub = app.add_subcommand("optimize", "Optimize a transfer function for FIELD to match REF rendered with REF-TF");
  add_input_options(sub, args->in, /*required=*/true);
  sub->add_option("--out", args->out, "Optimized transfer function (.json, .xml or .paraview.json)")->required();
  sub->add_option("--solver", args->solver, "Solver: " + solver_name_list() + " (described below)")
      ->capture_default_str();
  sub->add_option("--ridge", args->ridge, "Tikhonov weight, relative to the mean diagonal of M")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--smooth", args->smooth, "First-difference smoothness weight, relative to the mean diagonal of M (diffdvr: "
                  "weight of (N-1) sum of squared TF differences, added to the mean image loss)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--factorization", args->factorization, "normal-equations: auto, ldlt or qr")
      ->check(CLI::IsMember({"auto", "ldlt", "qr"}))->capture_default_str();
  sub->add_option("--json", args->json, "Also write the summary as JSON");
  add_solver_options(sub, args->extra);
  sub->add_option("--report", args->report, "Write a report into this directory: renderings before/after, residual "
                  "maps, TF plots, metrics.json, index.html");
  add_render_options(sub, args->render);
  sub->footer(solver_descriptions());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
