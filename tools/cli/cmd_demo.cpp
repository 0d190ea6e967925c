// `tfmatch demo`: a built-in pair of fields and a reference TF, optimized end to end.
#include <filesystem>
#include <iostream>
#include <map>

#include "atomic_file.h"
#include "cli.h"
#include "optimize.h"
#include "progress.h"
#include "render_options.h"
#include "report.h"
#include "loss_plot.h"
#include "result_json.h"
#include "solver_options.h"
#include "synthetic.h"
#include "volume_io.h"
#include "tf_json.h"

namespace tfm::cli {
namespace {

struct DemoArgs {
  std::string out = "tfmatch-demo";
  uint64_t size = 96;
  std::string solver = "normal-equations";
  std::string report;        // empty: the output directory
  bool no_report = false;
  RenderSettings render;
  std::map<std::string, std::string> extra;  // solver options (solver_options.h), as optimize has
};

int run(const DemoArgs& a) {
  SolverSettings settings;
  settings.render = a.render;  // image-based solvers render as the report does
  settings.extra = a.extra;
  parse_solver_args(require_solver(a.solver), settings);  // bad solver flags fail before any work
  if (!a.no_report) validate(a.render);
  std::filesystem::create_directories(a.out);
  const std::filesystem::path dir = a.out;
  Volume ref = synthetic_reference(a.size, a.size, a.size);
  Volume field = synthetic_remapped(ref);
  TransferFunction ref_tf = demo_transfer_function(64);
  const std::string dims = std::to_string(a.size) + "x" + std::to_string(a.size) + "x" + std::to_string(a.size);
  write_raw_float32(dir / ("reference_" + dims + "_float32.raw"), ref);
  write_raw_float32(dir / ("field_" + dims + "_float32.raw"), field);
  write_tf_json(dir / "reference_tf.json", ref_tf);

  OptimizeRequest req;
  req.ref = &ref;
  req.field = &field;
  req.ref_tf = ref_tf;
  req.tf_size = 64;
  req.solver = a.solver;
  req.settings = settings;
  auto ctx = make_context();
  req.voxel_mae = true;  // the report shows the mean absolute error
  OptimizeResult result = run_optimize(*ctx, req);
  write_tf_json(dir / "optimized_tf.json", result.tf);
  write_file_atomically(dir / "summary.json", to_json(result).dump(2) + "\n");
  if (!globals().quiet) {
    std::cout << "demo: reference = smooth blobs; field = nonlinear, partly non-monotone remap of it in other\n"
                 "      units, plus a sphere of real structural difference no TF can explain\n";
    result.print_summary(std::cout);
    std::cout << "  wrote " << dir.string() << "/{reference,field}_" << dims
              << "_float32.raw, reference_tf.json, optimized_tf.json, summary.json\n";
  }
  if (!a.no_report) {
    set_progress_enabled(!globals().quiet);
    const std::filesystem::path report_dir = a.report.empty() ? dir : std::filesystem::path(a.report);
    ReportInputs inputs{ref, field, ref_tf, result, a.render};
    inputs.extra_figures = solver_report_figures(result, a.render.width);  // diffdvr: loss curve
    inputs.title = "tfmatch demo: synthetic reference vs remapped field";
    ReportSummary summary = write_report(*ctx, inputs, report_dir);
    if (!globals().quiet)
      std::cout << "  images vs reference: reference TF " << summary.before.to_string() << "\n"
                << "                       optimized TF " << summary.after.to_string() << "\n"
                << "  report: " << summary.index.string() << "\n";
  }
  return 0;
}

CommandRegistration reg(0, [](CLI::App& app) {
  auto args = std::make_shared<DemoArgs>();
  auto* sub = app.add_subcommand("demo", "Run the optimizer on a built-in pair of fields and write the results");
  sub->add_option("--out", args->out, "Output directory")->capture_default_str();
  sub->add_option("--size", args->size, "Grid size per axis")->check(CLI::Range(8, 512))->capture_default_str();
  sub->add_option("--solver", args->solver, "Solver: " + solver_name_list() + " (described below)")
      ->capture_default_str();
  sub->add_option("--report", args->report, "Report directory (default: the output directory)");
  sub->add_flag("--no-report", args->no_report, "Skip the report (renderings, metrics, index.html)");
  add_solver_options(sub, args->extra);
  add_render_options(sub, args->render);
  sub->footer(solver_descriptions());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
