// `tfmatch optimize`: fit a TF for a second field to a reference field and its TF.
#include <iostream>
#include <map>
#include <optional>

#include "atomic_file.h"
#include "cli.h"
#include "input_options.h"
#include "optimize.h"
#include "output_check.h"
#include "output_options.h"
#include "progress.h"
#include "render.h"
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
  std::vector<std::string> markers;           // drawn on the report's renderings
  std::string slice_point;                    // the report's slices go through it
  std::string histogram = "log";              // report TF plots: log or linear counts
  RenderSettings render;
};

int run(const OptimizeArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  SolverSettings settings;
  settings.render = a.render;  // image-based solvers render as the report does
  settings.solve.ridge = a.ridge;
  settings.solve.smooth = a.smooth;
  settings.extra = a.extra;
  settings.solve.factorization = a.factorization == "ldlt" ? Factorization::LDLT : Factorization::Auto;
  // Bad or misapplied solver flags fail before loading, as usage errors.
  check_usage([&] { parse_solver_args(require_solver(a.solver), settings); });
  // Every file checked before any work: no output replaces an input or another output.
  FilePlan()
      .input_spec(a.in.ref, "--ref")
      .input_spec(a.in.field, "--field")
      .input_spec(a.in.ref_tf, "--ref-tf")
      .output(a.out, "--out")
      .output(json.file(), "--json")
      .output_directory(a.report, "--report", report_file_names())
      .check();
  if (!a.report.empty()) validate(a.render);  // fail before the solve, not after
  if (a.report.empty() && !a.markers.empty())
    throw CLI::ValidationError("--marker", "markers are drawn on the report's renderings: add --report DIR");
  if (a.report.empty() && !a.slice_point.empty())
    throw CLI::ValidationError("--slice-point", "slices are part of the report: add --report DIR");
  auto ctx = make_context();
  if (!a.report.empty()) check_render_size(*ctx, a.render);
  OutputBatch outputs;  // nothing appears unless every output is complete
  LoadedInputs loaded;
  load_inputs(a.in, loaded);
  const Volume& ref = loaded.ref;
  const std::vector<GridIndex> markers = resolve_markers(ref, a.markers);
  const std::optional<GridIndex> slice_point = resolve_slice_point(ref, a.slice_point);
  const Volume& field = loaded.field;
  OptimizeRequest& req = loaded.request;
  req.solver = a.solver;
  req.settings = settings;
  req.voxel_mae = !a.json.empty() || !a.report.empty();  // both show the mean absolute error
  OptimizeResult result = run_optimize(*ctx, req);
  if (!globals().quiet) result.print_summary(std::cout);
  write_transfer_function(a.out, result.tf);
  json.write(to_json(result));
  std::optional<ReportSummary> summary;
  if (!a.report.empty()) {
    set_progress_enabled(!globals().quiet);
    ReportInputs inputs{ref, field, req.ref_tf, result, a.render};
    inputs.extra_figures = solver_report_figures(result, a.render.width);  // diffdvr: loss curve
    inputs.title = "tfmatch: " + field.name + " matched to " + ref.name;
    inputs.markers = markers;
    inputs.slice_point = slice_point;
    inputs.histogram_log = a.histogram == "log";
    inputs.command_line = globals().command_line;
    inputs.version = version_line();
    inputs.inputs = input_args_json(a.in);
    inputs.inputs["solver"] = a.solver;
    inputs.inputs["solver_options"] = a.extra;
    inputs.inputs["ridge"] = a.ridge;
    inputs.inputs["smooth"] = a.smooth;
    summary = write_report(*ctx, inputs, a.report);
  }
  outputs.commit();
  if (!globals().quiet) {
    std::cout << "  wrote " << a.out << (json.file().empty() ? "" : " and " + a.json) << "\n";
    if (summary)
      std::cout << "  images vs reference: reference TF " << summary->before.to_string() << "\n"
                << "                       optimized TF " << summary->after.to_string() << "\n"
                << "  report: " << summary->index.string() << "\n";
  }
  return 0;
}

CommandRegistration reg(10, [](CLI::App& app) {
  auto args = std::make_shared<OptimizeArgs>();
  auto* sub = app.add_subcommand("optimize", "Optimize a transfer function for FIELD to match REF rendered with REF-TF");
  add_input_options(sub, args->in, /*required=*/true);
  sub->add_option("--out", args->out, "Optimized transfer function (.json, .xml or .paraview.json)")->required()
      ->check(output_format(transfer_function_format()));
  sub->add_option("--solver", args->solver, "Solver: " + solver_name_list() + " (described below)")
      ->capture_default_str();
  sub->add_option("--ridge", args->ridge, "Tikhonov weight, relative to the mean diagonal of M")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--smooth", args->smooth, "First-difference smoothness weight, relative to the mean diagonal of M (diffdvr: "
                  "weight of (N-1) sum of squared TF differences, added to the mean image loss)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--factorization", args->factorization, "normal-equations: auto (LDL^T deciding the rank entry by "
                  "entry: the minimum-norm solution when M is singular) or ldlt (no rank decision)")
      ->check(CLI::IsMember({"auto", "ldlt"}))->capture_default_str();
  add_json_option(sub, args->json, "the summary");
  add_solver_options(sub, args->extra);
  sub->add_option("--report", args->report, "Write a report into this directory: renderings before/after, residual "
                  "maps, TF plots, metrics.json, index.html");
  add_render_options(sub, args->render);
  add_marker_option(sub, args->markers);
  add_slice_point_option(sub, args->slice_point);
  add_histogram_option(sub, args->histogram);
  sub->footer(solver_descriptions());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
