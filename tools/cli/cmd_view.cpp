// `tfmatch view`: interactive inspection in the browser, served by tfmatch itself
// (host/viewer): the fields stay on the device, the page asks for pictures and optimizations.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>
#include <tuple>

#include "cli.h"
#include "input_options.h"
#include "interrupts.h"
#include "render_options.h"
#include "solver_options.h"
#include "tfmatch/io/ensemble_io.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/correlation_field.h"
#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/model/synthetic_ensemble.h"
#include "tfmatch/viewer/view_server.h"
#include "tfmatch/viewer/view_session.h"

namespace tfm::cli {
namespace {

struct ViewArgs {
  InputArgs in;                 // --ref, --ref-tf, --field, ranges, --tf-size, raw layout, selectors
  std::vector<std::string> fields;  // every --field, expanded: several make a series
  std::string report;           // reopen a report's inputs
  bool demo = false;            // the built-in pair (or, with --ensemble, the built-in ensemble)
  uint64_t size = 0;            // demo grid size (0: 96 for the pair, 64 for the ensemble)
  std::string ensemble;         // FILE[:VAR]; empty with --ensemble alone (the demo's)
  bool ensemble_given = false;
  std::vector<std::string> members;
  std::string member_dim, measure = "mi-coefficient", versus = "pearson", point;
  uint32_t bins = 16, k = 3;
  std::string solver;           // empty: as tfmatch demo for --demo's pair (irls), else normal-equations
  double ridge = 0.0, smooth = 0.0;
  std::map<std::string, std::string> extra;
  std::vector<std::string> markers;
  RenderSettings render;
  RenderChoices render_chosen;
  std::string bind = "127.0.0.1";
  int port = 8765;
};

bool is_loopback(const std::string& address) {
  return address == "127.0.0.1" || address == "localhost" || address == "::1" || address.rfind("127.", 0) == 0;
}

CorrelationMeasure measure_flag(const std::string& text, const std::string& flag) {
  try {
    return parse_correlation_measure(text);
  } catch (const std::invalid_argument& e) {
    throw CLI::ValidationError(flag, e.what());
  }
}

// The inputs a report recorded (report.h: inputs.json), as if given on the command line.
void inputs_from_report(const std::string& dir, InputArgs& in, ViewArgs& a) {
  const std::filesystem::path path = std::filesystem::path(dir) / "inputs.json";
  std::ifstream file(path);
  if (!file)
    throw std::runtime_error(path.string() + ": cannot read it (reports written by tfmatch 0.3 optimize --report or "
                             "demo record their inputs there)");
  const nlohmann::json j = nlohmann::json::parse(file, nullptr, false);
  if (j.is_discarded() || !j.is_object() || !j.contains("ref") || !j.contains("field") || !j.contains("ref_tf"))
    throw std::runtime_error(path.string() + ": not a tfmatch report's inputs (expected ref, field and ref_tf)");
  in = input_args_from_json(j, std::filesystem::path(dir));
  if (j.contains("solver") && j["solver"].is_string()) a.solver = j["solver"].get<std::string>();
  if (j.contains("solver_options") && j["solver_options"].is_object())
    for (const auto& [k, v] : j["solver_options"].items())
      if (v.is_string()) a.extra[k] = v.get<std::string>();
  a.ridge = j.value("ridge", 0.0);
  a.smooth = j.value("smooth", 0.0);
}

// Without --ref-tf a pair starts from a built-in map chosen by the reference's range (a signed
// field gets the diverging map, centred on zero so that zero is its transparent middle), and
// says so on stderr. Returns the words for the page's title.
std::string use_default_tf(const Volume& ref, ViewConfig& config) {
  const FiniteStats stats = finite_stats(ref.values);
  const FieldRange range = config.ref_range ? *config.ref_range : FieldRange{stats.lo, stats.hi};
  const BuiltinTf tf = default_builtin_tf(range);
  config.ref_tf = builtin_transfer_function(tf, kDefaultBuiltinTfSize);
  std::string why = "its range does not span zero";
  if (tf.name == "diverging") {
    why = "its range spans zero";
    const double m = std::max(-range.lo, range.hi);
    if (!config.ref_range && std::isfinite(m)) config.ref_tf.range = FieldRange{-m, m};
  }
  std::ostringstream note;
  note << "no --ref-tf: the reference " << ref.name << " starts with the built-in '" << tf.name
       << "' (" << builtin_tf_source(tf.name) << ", opacity " << opacity_shape_name(tf.opacity) << ") because "
       << why << " ([" << range.lo << ", " << range.hi << "])";
  if (config.ref_tf.range)
    note << "; mapped over [" << config.ref_tf.range->lo << ", " << config.ref_tf.range->hi << "] so that 0 is its middle";
  print_note(note.str() + "; --ref-tf NAME or FILE chooses another", "tfmatch view");
  return "reference TF: built-in " + tf.name + ", the default";
}

int run(ViewArgs a) {
  set_progress_enabled(!globals().quiet);
  const int modes = int(a.demo) + int(!a.report.empty()) + int(!a.in.ref.empty() || !a.in.field.empty()) +
                    int(!a.ensemble.empty() || !a.members.empty());
  if (modes != 1)
    throw CLI::ValidationError("view", "give one of: --ref/--ref-tf/--field (a pair of fields), --report DIR, "
                                       "--ensemble FILE[:VAR] (or --members), or --demo [--ensemble]");
  if (a.ensemble_given && a.ensemble.empty() && !a.demo && a.members.empty())
    throw CLI::ValidationError("--ensemble", "needs FILE[:VAR], or --demo for the built-in ensemble");
  const bool ensemble_mode = a.ensemble_given || !a.members.empty();
  if (!a.report.empty()) inputs_from_report(a.report, a.in, a);
  if (!ensemble_mode && !a.demo && (a.in.ref.empty() || a.in.field.empty()))
    throw CLI::ValidationError("view", "a pair of fields needs --ref and --field (and --ref-tf, else a built-in map)");
  // The demo pair opens with the fit `tfmatch demo` makes of it, so the page shows what the demo's
  // report shows.
  if (a.solver.empty()) a.solver = a.demo && !ensemble_mode ? kChangedPairSolver : "normal-equations";

  SolverSettings settings;
  settings.solve.ridge = a.ridge;
  settings.solve.smooth = a.smooth;
  settings.extra = a.extra;
  settings.render = a.render;
  check_usage([&] { parse_solver_args(require_solver(a.solver), settings); });
  validate(a.render);
  FilePlan plan;
  plan.input_spec(a.in.ref, "--ref").input_spec(a.in.ref_tf, "--ref-tf");
  for (size_t i = 0; i < a.fields.size(); ++i) plan.input_spec(a.fields[i], "--field " + std::to_string(i + 1));
  if (a.fields.empty()) plan.input_spec(a.in.field, "--field");
  plan.input_spec(a.ensemble, "--ensemble");
  plan.check();
  if (!is_loopback(a.bind))
    std::cerr << "tfmatch view: warning: listening on " << a.bind
              << ", not only this machine: anyone who can reach it and learns the URL's token can use it\n";

  auto ctx = make_context();
  check_render_size(*ctx, a.render);
  ViewConfig config;
  config.render = a.render;
  config.solver = a.solver;
  config.solver_settings = settings;
  config.tf_size = a.in.tf_size;
  config.allow_out_of_range = a.in.allow_out_of_range;
  if (!a.in.ref_range.empty()) config.ref_range = parse_range(a.in.ref_range, "--ref-range");
  if (!a.in.field_range.empty()) config.field_range = parse_range(a.in.field_range, "--field-range");
  if (!a.in.ref_tf.empty()) {
    std::vector<std::string> notes;
    config.ref_tf = read_transfer_function(a.in.ref_tf, {}, &notes);
    for (const auto& n : notes) print_note(n);
  }

  std::unique_ptr<ViewSession> session;
  if (ensemble_mode) {
    ViewEnsemble e;
    e.params.measure = measure_flag(a.measure, "--measure");
    e.versus = measure_flag(a.versus, "--versus");
    e.params.bins = a.bins;
    e.params.k = a.k;
    std::vector<std::string> files;  // the files read: none for the demo
    if (!a.demo) files = a.members.empty() ? std::vector<std::string>{a.ensemble} : expand_member_patterns(a.members);
    VolumeOptions vo = a.in.volume.options(files);
    vo.member_dim = a.member_dim;
    if (a.demo) {
      const uint64_t n = a.size ? a.size : 64;
      e.ensemble = synthetic_ensemble(n, n, std::max<uint64_t>(n / 2, 2), 64);
    } else {
      e.ensemble = a.members.empty() ? load_ensemble(a.ensemble, vo) : load_ensemble_members(files, vo);
    }
    check_correlation_members(e.ensemble);  // before resolving the point, as correlate does
    const Volume& grid = e.ensemble.grid;
    e.point = !a.point.empty()  ? resolve_point(grid, a.point, "--point")
              : a.demo          ? synthetic_ensemble_reference(e.ensemble)
                                : GridIndex{grid.dims[0] / 2, grid.dims[1] / 2, grid.dims[2] / 2};
    apply_grid_defaults(config.render, grid.dims, grid.spacing, a.render_chosen);
    // Its range: the measure's scale. On a map (a thin grid seen from above) weak dependence is
    // shown faintly rather than as holes in it.
    if (config.ref_tf.size() < 2)
      config.ref_tf = correlation_transfer_function(64, is_thin_grid(grid.dims, grid.spacing, config.render.z_scale) ? 0.1 : 0.0);
    config.title = std::string(correlation_measure_name(e.params.measure)) + " vs " + correlation_measure_name(e.versus) +
                   " of " + (a.demo ? std::string("the built-in ensemble") : grid.name);
    session = std::make_unique<ViewSession>(*ctx, std::move(e), config);
  } else if (a.fields.size() > 1) {
    // Series mode: one field at a time, chosen on the page.
    std::vector<std::string> inputs = a.fields;
    inputs.push_back(a.in.ref);
    const VolumeOptions vo = a.in.volume.options(inputs);
    Volume ref = load_volume(a.in.ref, vo);
    ViewSeries series;
    for (const std::string& f : a.fields) series.labels.push_back(std::filesystem::path(f).filename().string());
    series.load = [fields = a.fields, vo](size_t i) { return load_volume(fields[i], vo); };
    config.title = std::to_string(a.fields.size()) + " fields matched to " + ref.name;
    if (config.ref_tf.size() < 2) config.title += " (" + use_default_tf(ref, config) + ")";
    config.markers = resolve_markers(ref, a.markers);
    apply_grid_defaults(config.render, ref.dims, ref.spacing, a.render_chosen);
    session = std::make_unique<ViewSession>(*ctx, std::move(ref), std::move(series), config);
  } else {
    Volume ref, field;
    if (a.demo) {
      const uint64_t n = a.size ? a.size : 96;
      ref = synthetic_reference(n, n, n);
      field = synthetic_changed(ref);  // as `tfmatch demo`: a monotone remap with two real changes
      config.ref_tf = demo_transfer_function(64);
      config.title = "demo: synthetic reference vs a remapped field with real changes";
    } else {
      const VolumeOptions vo = a.in.volume.options({a.in.ref, a.in.field});
      std::tie(ref, field) = load_volume_pair(a.in.ref, a.in.field, vo);
      config.title = field.name + " matched to " + ref.name;
      if (config.ref_tf.size() < 2) config.title += " (" + use_default_tf(ref, config) + ")";
    }
    config.markers = resolve_markers(ref, a.markers);
    apply_grid_defaults(config.render, ref.dims, ref.spacing, a.render_chosen);
    session = std::make_unique<ViewSession>(*ctx, std::move(ref), std::move(field), config);
  }

  ViewServerOptions options;
  options.bind = a.bind;
  options.port = a.port;
  if (const char* dir = std::getenv("TFMATCH_VIEW_ASSETS"); dir && *dir) options.assets_dir = dir;
  ViewServer server(*session, options);
  // Ctrl-C is how a view ends: time to close the server, let a running job reach its next
  // checkpoint and release the device (seconds on a CPU device), then exit 0.
  set_interrupt_grace(std::chrono::seconds(20));
  server.start();
  std::cout << "tfmatch view: " << server.url() << "\n"
            << "  " << session->state()["title"].get<std::string>() << " on " << ctx->device_name()
            << "; open the URL in a browser (from another machine: ssh -L " << server.port() << ":localhost:"
            << server.port() << " HOST), Ctrl-C stops\n"
            << std::flush;
  while (!cancel_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  server.stop();
  session->wait_for_job();
  session.reset();
  reset_cancel();  // stopping is how a view ends: exit 0
  if (!globals().quiet) std::cout << "tfmatch view: stopped\n";
  return 0;
}

CommandRegistration reg(15, [](CLI::App& app) {
  auto args = std::make_shared<ViewArgs>();
  auto* sub = app.add_subcommand(
      "view",
      "Serve an interactive page (reference, field with each TF, residual; slices; TF plots; solvers; TF editor; "
      "ensemble reference points) rendered by tfmatch on the device. Prints the URL; Ctrl-C stops. Only this machine "
      "can connect by default, and every request needs the URL's random token");
  add_input_options(sub, args->in, /*required=*/false);
  // --field takes several fields here: the page shows one at a time, chosen with a slider.
  sub->remove_option(sub->get_option("--field"));
  sub->add_option("--field", args->fields, "Field whose transfer function is optimized; several (as optimize: repeat "
                  "--field, FILE:VAR,time=A..B or member=A..B, a quoted pattern) show one at a time, chosen on the page");
  sub->footer("Without --ref-tf a pair of fields starts from a built-in map: 'diverging' (opacity vee, mapped "
              "symmetrically about 0) when the reference's range spans zero, else 'viridis'; a note on stderr and the "
              "page's title say which.");
  sub->add_option("--report", args->report, "Reopen the inputs of a report directory (optimize --report, demo)");
  sub->add_flag("--demo", args->demo, "The built-in pair of fields of `tfmatch demo` (with --ensemble: the built-in ensemble)");
  sub->add_option("--size", args->size, "--demo: grid size (default 96 for the pair, 64 for the ensemble)")
      ->check(CLI::Range(uint64_t(8), uint64_t(512)));
  auto* ens = sub->add_option("--ensemble", args->ensemble,
                              "Ensemble mode: FILE[:VAR] with a member axis (as correlate), or alone with --demo");
  ens->expected(0, 1);
  sub->add_option("--members", args->members, "Ensemble as one file per member (as correlate)");
  sub->add_option("--member-dim", args->member_dim, "NetCDF: the name of the member dimension");
  sub->add_option("--measure", args->measure, "Ensemble: the reference field's measure (as correlate --measure)")
      ->capture_default_str();
  sub->add_option("--versus", args->versus, "Ensemble: the measure of the field whose TF is optimized")
      ->capture_default_str();
  sub->add_option("--point", args->point, "Ensemble: first reference point, I,J,K or lon=..,lat=..,level=.. "
                                          "(default: the grid's middle; the demo's own point)");
  sub->add_option("--bins", args->bins, "mi-binned: bins")->check(CLI::Range(2u, kMaxCorrelationBins))->capture_default_str();
  sub->add_option("--k", args->k, "mi-kraskov, mi-coefficient: neighbours")->check(positive())->capture_default_str();
  sub->add_option("--solver", args->solver,
                  "First solver: " + solver_name_list() +
                      " (default: irls for --demo's pair, as tfmatch demo; normal-equations otherwise; the page can "
                      "choose another)");
  sub->add_option("--ridge", args->ridge, "Tikhonov weight, relative to the mean diagonal of M")->check(non_negative());
  sub->add_option("--smooth", args->smooth, "Smoothness weight, relative to the mean diagonal of M")->check(non_negative());
  add_solver_options(sub, args->extra);
  add_render_options(sub, args->render);
  add_marker_option(sub, args->markers);
  sub->add_option("--port", args->port, "TCP port (0: any free port)")->check(CLI::Range(0, 65535))->capture_default_str();
  sub->add_option("--bind", args->bind, "Address to listen on (default: this machine only; another prints a warning)")
      ->check(CLI::Validator(
          [](std::string& address) -> std::string {
            // An empty address listened on some interface while the printed URL named 127.0.0.1.
            if (address.empty() || address.find_first_of(" \t") != std::string::npos)
              return "expected an address such as 127.0.0.1 or 0.0.0.0, got '" + address + "'";
            return {};
          },
          ""))
      ->capture_default_str();
  sub->callback([args, ens, sub] {
    args->ensemble_given = ens->count() > 0;
    args->fields = expand_field_specs(args->fields, "--field");
    if (!args->fields.empty()) args->in.field = args->fields.front();
    args->render_chosen = render_choices(*sub);
    exit_code() = run(*args);
  });
});

}  // namespace
}  // namespace tfm::cli
