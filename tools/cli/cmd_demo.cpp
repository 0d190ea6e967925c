// `tfmatch demo`: a built-in pair of fields and a reference TF, optimized end to end.
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>

#include "atomic_file.h"
#include "correlation_field.h"
#include "cli.h"
#include "optimize.h"
#include "output_check.h"
#include "progress.h"
#include "render.h"
#include "render_options.h"
#include "report.h"
#include "loss_plot.h"
#include "result_json.h"
#include "solver_options.h"
#include "synthetic.h"
#include "synthetic_ensemble.h"
#include "volume_vti.h"
#include "volume_io.h"
#include "tf_json.h"

namespace tfm::cli {
namespace {

struct DemoArgs {
  std::string out = "tfmatch-demo";
  uint64_t size = 0;         // 0: 96 for the field pair, 64 for the ensemble
  std::string solver = "normal-equations";
  std::string report;        // empty: the output directory
  bool no_report = false;
  bool ensemble = false;     // the ensemble use case instead of the field pair
  uint32_t members = 64;
  RenderSettings render;
  std::string histogram = "log";             // report TF plots: log or linear counts
  std::map<std::string, std::string> extra;  // solver options (solver_options.h), as optimize has
};

// What the demo optimizes: two fields on one grid, the reference TF, and what to say about them.
struct DemoInputs {
  Volume ref, field;
  TransferFunction ref_tf;
  std::string title, description;
  std::vector<std::string> written;  // files written so far, relative to the output directory
  std::vector<GridIndex> markers;
};

// The classic demo: smooth blobs vs a nonlinear remap of them with a sphere of real difference.
DemoInputs fields_demo(const DemoArgs& a, const std::filesystem::path& dir) {
  DemoInputs in;
  const uint64_t n = a.size ? a.size : 96;
  in.ref = synthetic_reference(n, n, n);
  in.field = synthetic_remapped(in.ref);
  in.ref_tf = demo_transfer_function(64);
  const std::string dims = std::to_string(n) + "x" + std::to_string(n) + "x" + std::to_string(n);
  for (const auto& [name, v] : {std::pair{"reference_", &in.ref}, std::pair{"field_", &in.field}}) {
    const std::string file = name + dims + "_float32.raw";
    write_raw_float32(dir / file, *v);
    in.written.push_back(file);
  }
  in.title = "tfmatch demo: synthetic reference vs remapped field";
  in.description =
      "demo: reference = smooth blobs; field = nonlinear, partly non-monotone remap of it in other\n"
      "      units, plus a sphere of real structural difference no TF can explain\n";
  return in;
}

// The paper's ensemble use case on a built-in ensemble: the mutual-information field of a
// reference point (as the MI coefficient, on [0, 1]) is the reference, the Pearson field of the
// same point the second field.
DemoInputs ensemble_demo(Context& ctx, const DemoArgs& a, const std::filesystem::path& dir) {
  const uint64_t n = a.size ? a.size : 64;
  const Ensemble ens = synthetic_ensemble(n, n, std::max<uint64_t>(n / 2, 2), a.members);
  const GridIndex point = synthetic_ensemble_reference(ens);
  DemoInputs in;
  CorrelationRequest request;
  request.point = linear_index(ens.grid, point);
  Progress progress("correlation fields", 2 * ens.voxel_count());
  for (auto [measure, volume, pass] : {std::tuple{CorrelationMeasure::MiCoefficient, &in.ref, 0},
                                       std::tuple{CorrelationMeasure::Pearson, &in.field, 1}}) {
    request.params.measure = measure;
    *volume = empty_like(ens.grid);
    volume->name = std::string(correlation_measure_name(measure)) + " field of the synthetic ensemble";
    volume->values = correlation_field(ctx, ens.view(), request, [&, pass = pass](uint64_t done, uint64_t total) {
      progress.update(uint64_t(pass) * total + done);
    });
    const std::string file = std::string(correlation_measure_name(measure)) + ".vti";
    write_vti(dir / file, *volume, correlation_measure_name(measure));
    in.written.push_back(file);
  }
  progress.finish();
  in.ref_tf = correlation_transfer_function(64);
  in.ref_tf.range = FieldRange{0.0, 1.0};  // the MI coefficient's own scale
  in.markers = {point};
  in.title = "tfmatch demo: mutual information vs Pearson correlation of an ensemble";
  in.description = "demo --ensemble: " + std::to_string(ens.member_count) + " members on " + std::to_string(n) + "x" +
                   std::to_string(n) + "x" + std::to_string(ens.grid.dims[2]) + "; reference point " +
                   describe_grid_point(ens.grid, point) +
                   ";\n      reference = mutual information (KSG, k = 3, as the coefficient sqrt(1 - exp(-2 MI)) in\n"
                   "      [0, 1]), field = Pearson correlation; the TF of the\n"
                   "      Pearson field is optimized so it looks like the MI field; the residual shows where the\n"
                   "      measures disagree (a non-monotone dependence Pearson cannot see)\n";
  return in;
}

// Whether the report goes into the demo's own directory; it then writes both TFs there itself.
bool report_in_out_dir(const DemoArgs& a) { return !a.no_report && a.report.empty(); }

// The files the demo writes into its output directory (besides the report's).
std::vector<std::string> demo_file_names(const DemoArgs& a) {
  std::vector<std::string> names = {"summary.json"};
  if (!report_in_out_dir(a)) names.insert(names.end(), {"reference_tf.json", "optimized_tf.json"});
  if (a.ensemble) {
    for (CorrelationMeasure m : {CorrelationMeasure::MiCoefficient, CorrelationMeasure::Pearson})
      names.push_back(std::string(correlation_measure_name(m)) + ".vti");
  } else {
    const uint64_t n = a.size ? a.size : 96;
    const std::string dims = std::to_string(n) + "x" + std::to_string(n) + "x" + std::to_string(n);
    for (const char* name : {"reference_", "field_"}) names.push_back(name + dims + "_float32.raw");
  }
  return names;
}

int run(const DemoArgs& a) {
  SolverSettings settings;
  settings.render = a.render;  // image-based solvers render as the report does
  settings.extra = a.extra;
  check_usage([&] { parse_solver_args(require_solver(a.solver), settings); });  // before any work
  const std::filesystem::path report_dir = a.report.empty() ? std::filesystem::path(a.out) : std::filesystem::path(a.report);
  FilePlan()
      .output_directory(a.out, "--out", demo_file_names(a))
      .output_directory(a.no_report ? std::filesystem::path() : report_dir, a.report.empty() ? "--out" : "--report",
                        report_file_names())
      .check();
  if (!a.no_report) validate(a.render);
  auto ctx = make_context();
  if (!a.no_report) check_render_size(*ctx, a.render);
  OutputBatch outputs;  // the directory and its files appear when the demo is complete
  const std::filesystem::path dir = outputs.directory(a.out);
  set_progress_enabled(!globals().quiet);
  DemoInputs in = a.ensemble ? ensemble_demo(*ctx, a, dir) : fields_demo(a, dir);
  if (!report_in_out_dir(a)) write_tf_json(dir / "reference_tf.json", in.ref_tf);

  OptimizeRequest req;
  req.ref = &in.ref;
  req.field = &in.field;
  req.ref_tf = in.ref_tf;
  req.tf_size = 64;
  req.solver = a.solver;
  req.settings = settings;
  req.voxel_mae = true;  // the report shows the mean absolute error
  OptimizeResult result = run_optimize(*ctx, req);
  if (!report_in_out_dir(a)) write_tf_json(dir / "optimized_tf.json", result.tf);
  write_file_atomically(dir / "summary.json", to_json(result).dump(2) + "\n");
  if (!globals().quiet) {
    std::cout << in.description;
    result.print_summary(std::cout);
  }
  std::optional<ReportSummary> summary;
  if (!a.no_report) {
    ReportInputs inputs{in.ref, in.field, in.ref_tf, result, a.render};
    inputs.extra_figures = solver_report_figures(result, a.render.width);  // diffdvr: loss curve
    inputs.title = in.title;
    inputs.markers = in.markers;
    inputs.histogram_log = a.histogram == "log";
    inputs.command_line = globals().command_line;
    inputs.version = version_line();
    // `tfmatch view --report` reopens the demo's fields and reference TF where the demo leaves them.
    const std::filesystem::path final_out = std::filesystem::absolute(a.out);
    inputs.inputs = {{"ref", (final_out / in.written.at(0)).string()},
                     {"field", (final_out / in.written.at(1)).string()},
                     {"ref_tf", (final_out / "reference_tf.json").string()},
                     {"tf_size", 64},
                     {"solver", a.solver},
                     {"solver_options", a.extra}};
    summary = write_report(*ctx, inputs, report_dir);
  }
  outputs.commit();
  if (!globals().quiet) {
    std::cout << "  wrote " << a.out << "/{";
    for (const auto& f : in.written) std::cout << f << ", ";
    std::cout << "reference_tf.json, optimized_tf.json, summary.json}\n";
    if (summary)
      std::cout << "  images vs reference: reference TF " << summary->before.to_string() << "\n"
                << "                       optimized TF " << summary->after.to_string() << "\n"
                << "  report: " << summary->index.string() << "\n";
  }
  return 0;
}

CommandRegistration reg(0, [](CLI::App& app) {
  auto args = std::make_shared<DemoArgs>();
  auto* sub = app.add_subcommand("demo", "Run the optimizer on a built-in pair of fields and write the results");
  sub->add_option("--out", args->out, "Output directory")->capture_default_str();
  sub->add_option("--size", args->size, "Grid size per axis (default 96; with --ensemble 64, and half of it along z)")
      ->check(CLI::Range(8, 512));
  sub->add_option("--solver", args->solver, "Solver: " + solver_name_list() + " (described below)")
      ->capture_default_str();
  sub->add_option("--report", args->report, "Report directory (default: the output directory)");
  sub->add_flag("--no-report", args->no_report, "Skip the report (renderings, metrics, index.html)");
  sub->add_flag("--ensemble", args->ensemble,
                "The ensemble use case: mutual-information vs Pearson correlation fields of a built-in ensemble "
                "(--size 64 by default: about 20 s on lavapipe)");
  sub->add_option("--members", args->members, "--ensemble: ensemble members")->check(CLI::Range(3u, 4096u))
      ->capture_default_str();
  add_solver_options(sub, args->extra);
  add_render_options(sub, args->render);
  add_histogram_option(sub, args->histogram);
  sub->footer(solver_descriptions());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
