// `tfmatch optimize`: fit a TF for a second field to a reference field and its TF.
#include <fstream>
#include <iostream>
#include <map>

#include "atomic_file.h"
#include "cli.h"
#include "optimize.h"
#include "progress.h"
#include "render_options.h"
#include "report.h"
#include "solver_diffdvr_plot.h"
#include "tf_formats.h"
#include "volume.h"

namespace tfm::cli {
namespace {

struct OptimizeArgs {
  std::string ref, ref_tf, field, out, json;
  uint32_t tf_size = 64;
  std::string solver = "normal-equations";
  double ridge = 0.0, smooth = 0.0;
  std::string factorization = "auto";
  std::string ref_range, field_range;
  std::vector<uint64_t> dims;
  std::string type;
  bool big_endian = false;
  std::string var;                            // NetCDF variable / GRIB shortName / VTK array
  std::optional<uint64_t> time, member;       // NetCDF/GRIB time and member indices
  std::map<std::string, std::string> extra;  // solver-specific flags, passed through
  std::string report;                         // report directory (renderings, metrics, index.html)
  RenderSettings render;
};

// Solver-specific flags: each solver reads those it understands from SolverSettings::extra.
const std::pair<const char*, const char*> kSolverFlags[] = {
    {"loss", "gradient-descent/diffdvr: l2 or l1"},
    {"optimizer", "gradient-descent: adam or sgd; diffdvr: adam"},
    {"lr", "gradient-descent/diffdvr: learning rate"},
    {"iterations", "gradient-descent/diffdvr: iterations"},
    {"tolerance", "iterative solvers: relative residual of the normal equations to stop at"},
    {"max-iterations", "iterative solvers: iteration cap"},
    {"seed", "diffdvr: seed of the random cameras"},
    {"views-per-iteration", "diffdvr: cameras per iteration"},
    {"image-size", "diffdvr: image width and height in pixels"},
    {"init", "diffdvr: initial TF, reference or normal-equations"},
    {"cameras", "diffdvr: random or fibonacci"},
};

int run(const OptimizeArgs& a) {
  VolumeOptions vo;
  if (!a.dims.empty()) vo.dims = std::array<uint64_t, 3>{a.dims[0], a.dims[1], a.dims[2]};
  if (!a.type.empty()) {
    vo.type = parse_scalar_type(a.type);
    if (vo.type == ScalarType::Unknown) throw std::runtime_error("--type: unknown element type '" + a.type + "'");
  }
  vo.big_endian = a.big_endian;
  vo.variable = a.var;
  vo.time_index = a.time;
  vo.member_index = a.member;
  Volume ref = load_volume(a.ref, vo);
  Volume field = load_volume(a.field, vo);
  OptimizeRequest req;
  req.ref = &ref;
  req.field = &field;
  std::vector<std::string> tf_notes;
  req.ref_tf = read_transfer_function(a.ref_tf, {}, &tf_notes);
  for (const auto& n : tf_notes) std::cerr << "tfmatch: note: " << n << "\n";
  if (!a.ref_range.empty()) req.ref_range = parse_range(a.ref_range, "--ref-range");
  if (!a.field_range.empty()) req.field_range = parse_range(a.field_range, "--field-range");
  req.tf_size = a.tf_size;
  req.solver = a.solver;
  req.settings.render = a.render;  // image-based solvers render as the report does
  req.settings.solve.ridge = a.ridge;
  req.settings.solve.smooth = a.smooth;
  req.settings.extra = a.extra;
  req.settings.solve.factorization = a.factorization == "ldlt" ? Factorization::LDLT
                                     : a.factorization == "qr" ? Factorization::QR
                                                               : Factorization::Auto;
  if (!a.report.empty()) validate(a.render);  // fail before the solve, not after
  auto ctx = make_context();
  OptimizeResult result = run_optimize(*ctx, req);
  write_transfer_function(a.out, result.tf);
  if (!a.json.empty()) write_file_atomically(a.json, result.to_json().dump(2) + "\n");
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
  sub->add_option("--ref", args->ref, "Reference field: FILE or FILE:VAR[@LEVELTYPE][,time=N][,member=N]")->required();
  sub->add_option("--ref-tf", args->ref_tf, "Reference transfer function: tfmatch JSON, framework XML or ParaView "
                  "preset (FILE:PRESET picks one)")->required();
  sub->add_option("--field", args->field, "Field whose transfer function is optimized")->required();
  sub->add_option("--out", args->out, "Optimized transfer function (.json, .xml or .paraview.json)")->required();
  sub->add_option("--tf-size", args->tf_size, "Entries N of the optimized TF")->check(CLI::Range(2u, 1u << 16))
      ->capture_default_str();
  sub->add_option("--solver", args->solver, "Solver: " + [] {
    std::string s;
    for (auto& n : solver_names()) s += (s.empty() ? "" : ", ") + n;
    return s;
  }())->capture_default_str();
  sub->add_option("--ridge", args->ridge, "Tikhonov weight, relative to the mean diagonal of M")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--smooth", args->smooth, "First-difference smoothness weight, relative to the mean diagonal of M (diffdvr: "
                  "weight of (N-1) sum of squared TF differences, added to the mean image loss)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--factorization", args->factorization, "normal-equations: auto, ldlt or qr")
      ->check(CLI::IsMember({"auto", "ldlt", "qr"}))->capture_default_str();
  sub->add_option("--ref-range", args->ref_range, "Reference field range lo,hi (default: TF file's, else finite min/max)");
  sub->add_option("--field-range", args->field_range, "Field range lo,hi (default: finite min/max)");
  sub->add_option("--dims", args->dims, "Raw files: grid size X Y Z (when the file name does not say)")->expected(3)
      ->delimiter(',');
  sub->add_option("--type", args->type, "Raw files: element type (uint8, uint16, int16, float32, float64, ...)");
  sub->add_flag("--big-endian", args->big_endian, "Raw files: big-endian data");
  sub->add_option("--var", args->var, "NetCDF variable / GRIB shortName[@typeOfLevel] / VTK array, for both fields "
                  "unless FILE:VAR says otherwise");
  sub->add_option("--time", args->time, "NetCDF/GRIB time index (default 0; FILE:VAR,time=N per field)");
  sub->add_option("--member", args->member, "NetCDF/GRIB ensemble member / extra dimension index (default 0)");
  sub->add_option("--json", args->json, "Also write the summary as JSON");
  for (const auto& [flag, help] : kSolverFlags) {
    std::string name = flag;
    sub->add_option_function<std::string>("--" + name, [args, name](const std::string& v) { args->extra[name] = v; },
                                           help);
  }
  sub->add_option("--report", args->report, "Write a report into this directory: renderings before/after, residual "
                  "maps, TF plots, metrics.json, index.html");
  add_render_options(sub, args->render);
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
