// The viewer's session: fields and TFs on the device, pictures on request, jobs on a thread.
#include "tfmatch/viewer/view_session.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <utility>

#include "tfmatch/io/tf_json.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/kernels/correlation_field.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/color_spaces.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/slice.h"
#include "tfmatch/report/font.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/report/result_json.h"
#include "tfmatch/report/tf_plot.h"
#include "tfmatch/viewer/tf_points.h"
#include "tfmatch/viewer/view_session_derived.h"

namespace tfm {

namespace {

constexpr const char* kViewNames[] = {"reference", "field-ref-tf", "field-opt-tf", "residual", "residual-before"};

std::string exact_number(double x) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

std::string short_number(double x) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%g", x);
  return buf;
}

// The default reference TF of an ensemble view: the correlation colour map on the measure's own
// scale (mutual information has none: its data range).
std::optional<FieldRange> measure_scale(CorrelationMeasure m) {
  switch (m) {
    case CorrelationMeasure::Pearson:
    case CorrelationMeasure::Spearman:
    case CorrelationMeasure::Kendall: return FieldRange{-1.0, 1.0};
    case CorrelationMeasure::MiCoefficient: return FieldRange{0.0, 1.0};
    default: return std::nullopt;
  }
}

nlohmann::json option_json(const SolverOption& o) {
  static const char* kTypes[] = {"integer", "number", "choice", "text", "flag"};
  nlohmann::json j = {{"name", o.name},
                      {"type", kTypes[int(o.type)]},
                      {"default", o.describe_default()},
                      {"values", o.describe_values()},
                      {"help", o.help}};
  if (!o.choices.empty()) j["choices"] = o.choices;
  return j;
}

nlohmann::json solvers_json() {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& s : solvers()) {
    const SolverConstraints c = s->constraints();
    nlohmann::json options = nlohmann::json::array();
    for (const SolverOption& o : s->options()) options.push_back(option_json(o));
    list.push_back({{"name", std::string(s->name())},
                    {"summary", std::string(s->summary())},
                    {"image_based", s->image_based()},
                    {"box", box_handling_name(c.box)},
                    {"ridge", c.ridge},
                    {"smooth", c.smooth},
                    {"options", options}});
  }
  return list;
}

nlohmann::json range_json(const FieldRange& r) { return nlohmann::json::array({r.lo, r.hi}); }

}  // namespace

std::optional<ViewKind> parse_view_kind(std::string_view name) {
  for (int k = 0; k < 5; ++k)
    if (name == kViewNames[k]) return ViewKind(k);
  return std::nullopt;
}

const char* view_kind_name(ViewKind view) { return kViewNames[int(view)]; }


ViewSession::ViewSession(Context& ctx, Volume ref, Volume field, ViewConfig config)
    : ctx_(ctx), config_(std::move(config)), ref_(std::move(ref)), field_(std::move(field)) {
  require_same_grid(ref_, field_);
  initialize();
}

ViewSession::ViewSession(Context& ctx, ViewEnsemble ensemble, ViewConfig config)
    : ctx_(ctx), config_(std::move(config)), ensemble_(std::move(ensemble)) {
  check_correlation_members(ensemble_->ensemble);
  validate_correlation_params(ensemble_->params, ensemble_->ensemble.member_count);
  if (config_.ref_tf.size() >= 2 && !config_.ref_tf.range && !config_.ref_range)
    config_.ref_tf.range = measure_scale(ensemble_->params.measure);
  auto fields = correlation_fields(ensemble_->point);
  ref_ = std::move(fields.first);
  field_ = std::move(fields.second);
  initialize();
}

ViewSession::ViewSession(Context& ctx, Volume ref, ViewSeries series, ViewConfig config)
    : ctx_(ctx), config_(std::move(config)), series_(std::move(series)) {
  if (series_->labels.empty() || !series_->load || series_->index >= series_->labels.size())
    throw std::invalid_argument("series view: no fields, or a field index past them");
  ref_ = std::move(ref);
  field_ = series_->load(series_->index);
  initialize();
}

ViewSession::~ViewSession() {
  if (job_thread_.joinable()) job_thread_.join();
}

void ViewSession::initialize() {
  install_report_font();  // plot labels in DejaVu Sans where installed, as in reports
  validate(config_.render);
  ref_tf_ = config_.ref_tf;
  solver_ = config_.solver;
  solver_settings_ = config_.solver_settings;
  solver_settings_.render = config_.render;
  std::lock_guard device(device_mutex_);
  OptimizeResult result = run_optimization(ref_, field_, ref_tf_, solver_, solver_settings_);
  auto derived = derive(ref_, field_, ref_tf_, result);
  std::lock_guard data(data_mutex_);
  result_ = std::move(result);
  derived_ = std::move(derived);
  version_ = 1;
}

OptimizeResult ViewSession::run_optimization(const Volume& ref, const Volume& field, const TransferFunction& ref_tf,
                                             const std::string& solver, const SolverSettings& settings) {
  OptimizeRequest req;
  req.ref = &ref;
  req.field = &field;
  req.ref_tf = ref_tf;
  req.ref_range = config_.ref_range;
  req.field_range = config_.field_range;
  req.tf_size = config_.tf_size;
  req.solver = solver;
  req.settings = settings;
  req.settings.render = config_.render;  // image-based solvers render what the page shows
  req.allow_out_of_range = config_.allow_out_of_range;
  return run_optimize(ctx_, req);
}

std::unique_ptr<ViewSession::Derived> ViewSession::derive(const Volume& ref, const Volume& field,
                                                          const TransferFunction& ref_tf, const OptimizeResult& r,
                                                          const Derived* same_fields) {
  auto d = std::make_unique<Derived>();
  d->geometry = VolumeGeometry::from(ref.dims, ref.spacing, config_.render.z_scale);
  d->axes = ref.axes;
  // What the session holds beside the loaded fields, checked before any of it is made (the view
  // of two 64 MiB fields held 610 MiB at a budget of 210 MiB): both fields and both residual maps
  // on the device, and the residual maps on the host. A CPU device reads the fields and maps where
  // they are in host memory (field_over_host_values): then only a map being made is its own.
  const uint64_t volume_bytes = uint64_t(ref.values.size()) * sizeof(float);
  const uint64_t device_volumes = DeviceField::reads_host_memory(ctx_) ? 1 : same_fields ? 2 : 4;
  check_device_memory(ctx_, device_volumes * volume_bytes,
                      "view: " + std::string(same_fields ? "the residual maps" : "both fields and the residual maps") +
                          " on the device");
  check_memory(2 * volume_bytes, "view: the residual maps");
  if (same_fields) {
    d->ref = same_fields->ref;
    d->field = same_fields->field;
    d->ref_renderer = same_fields->ref_renderer;
    d->field_renderer = same_fields->field_renderer;
  } else {
    // `ref` and `field` are the session's volumes, or become them by a move (install(), set_field):
    // their values stay where they are while these fields read them.
    auto ref_dev = std::make_shared<DeviceField>(field_over_host_values(ctx_, ref.values, "view: reference field"));
    auto field_dev = std::make_shared<DeviceField>(
        field_over_host_values(ctx_, field.values, "view: second field", ref_dev->chunk_voxels()));
    d->ref_renderer = std::make_shared<GpuRenderer>(ctx_, *ref_dev, d->geometry);
    d->field_renderer = std::make_shared<GpuRenderer>(ctx_, *field_dev, d->geometry);
    d->ref = std::move(ref_dev);
    d->field = std::move(field_dev);
  }
  d->ref_tf.emplace(upload_tf(ctx_, ref_tf, "view: reference TF"));
  d->opt_tf.emplace(upload_tf(ctx_, r.tf, "view: optimized TF"));
  const uint32_t ref_n = uint32_t(ref_tf.size()), opt_n = uint32_t(r.tf.size());
  d->ref_map = make_mapping(r.ref_range, ref_n);
  d->field_ref_map = make_mapping(r.field_range, ref_n);
  d->field_opt_map = make_mapping(r.field_range, opt_n);
  d->res_before = residual_map_gpu(ctx_, ref, *d->ref, *d->field, d->ref_map, d->field_ref_map, *d->ref_tf, *d->ref_tf);
  d->res_after = residual_map_gpu(ctx_, ref, *d->ref, *d->field, d->ref_map, d->field_opt_map, *d->ref_tf, *d->opt_tf);
  d->res_range = residual_display_range({&d->res_before, &d->res_after});
  d->res_tf_table = residual_transfer_function();
  d->res_tf.emplace(upload_tf(ctx_, d->res_tf_table, "view: residual TF"));
  d->res_map = make_mapping(d->res_range, uint32_t(d->res_tf_table.size()));
  d->residual_before = std::make_unique<DeviceField>(field_over_host_values(ctx_, d->res_before.values, "view: residual before"));
  d->residual_after = std::make_unique<DeviceField>(field_over_host_values(ctx_, d->res_after.values, "view: residual after"));
  d->res_before_renderer = std::make_unique<GpuRenderer>(ctx_, *d->residual_before, d->geometry);
  d->res_after_renderer = std::make_unique<GpuRenderer>(ctx_, *d->residual_after, d->geometry);
  return d;
}

void ViewSession::install(std::optional<std::pair<Volume, Volume>> fields, TransferFunction ref_tf,
                          OptimizeResult result, std::unique_ptr<Derived> derived, const std::string& solver,
                          const SolverSettings& settings) {
  std::lock_guard data(data_mutex_);  // the caller holds device_mutex_
  // The old state first: its device fields may read the volumes replaced below in place
  // (field_over_host_values), and imported memory must outlive its device memory. The new
  // state's read `fields`' values, which a move leaves where they are.
  std::unique_ptr<Derived> old = std::exchange(derived_, std::move(derived));
  old.reset();
  if (fields) {
    ref_ = std::move(fields->first);
    field_ = std::move(fields->second);
  }
  ref_tf_ = std::move(ref_tf);
  result_ = std::move(result);
  solver_ = solver;
  solver_settings_ = settings;
  ++version_;
}

std::pair<Volume, Volume> ViewSession::correlation_fields(const GridIndex& point) {
  const ViewEnsemble& e = *ensemble_;
  const Volume& grid = e.ensemble.grid;
  for (int k = 0; k < 3; ++k)
    if (point[size_t(k)] >= grid.dims[size_t(k)])
      throw std::invalid_argument("reference point " + std::to_string(point[0]) + "," + std::to_string(point[1]) + "," +
                                  std::to_string(point[2]) + " is outside the grid");
  CorrelationRequest request;
  request.point = linear_index(grid, point);
  request.params = e.params;
  check_reference_point(e.ensemble.view(), request.point, e.params.measure);
  check_reference_point(e.ensemble.view(), request.point, e.versus);
  std::pair<Volume, Volume> out{empty_like(grid), empty_like(grid)};
  Progress progress("correlation fields", 2 * e.ensemble.voxel_count());
  int pass = 0;
  for (auto [measure, volume] : {std::pair{e.params.measure, &out.first}, std::pair{e.versus, &out.second}}) {
    request.params.measure = measure;
    volume->name = std::string(correlation_measure_name(measure)) + " field";
    volume->values = correlation_field(ctx_, e.ensemble.view(), request, [&](uint64_t done, uint64_t total) {
      progress.update(uint64_t(pass) * total + done);
    });
    ++pass;
  }
  return out;
}

// ---- jobs -------------------------------------------------------------------------------------

uint64_t ViewSession::start_job(const std::string& kind, std::function<void()> work) {
  std::lock_guard lock(job_mutex_);
  if (job_running_) throw ConflictError("a job is running (" + job_.kind + "): wait for it to end");
  if (job_thread_.joinable()) job_thread_.join();  // the previous job's thread has ended
  job_ = JobStatus{job_.id + 1, kind, "running", kind, "", 0, 0, std::chrono::steady_clock::now(), {}, nullptr};
  job_running_ = true;
  job_thread_ = std::thread([this, work = std::move(work)] {
    // Progress made by the solvers on this thread reaches the page.
    ScopedProgressObserver observer([this](const std::string& label, uint64_t done, uint64_t total) {
      std::lock_guard status(job_mutex_);
      job_.label = label;
      job_.done = done;
      job_.total = total;
    });
    std::string error;
    try {
      work();
    } catch (const Cancelled&) {
      error = "cancelled: tfmatch view is stopping";
    } catch (const std::exception& e) {
      error = e.what();
    }
    std::lock_guard status(job_mutex_);
    job_.state = error.empty() ? "done" : "failed";
    job_.error = error;
    job_.end = std::chrono::steady_clock::now();
    job_running_ = false;
  });
  return job_.id;
}

uint64_t ViewSession::optimize(const std::string& solver, const SolverSettings& settings_in) {
  SolverSettings settings = settings_in;
  settings.render = config_.render;
  parse_solver_args(require_solver(solver), settings);  // bad options fail the request, not the job
  return start_job("optimize", [this, solver, settings] { optimize_job(ref_tf_, solver, settings); });
}

void ViewSession::optimize_job(const TransferFunction& ref_tf_in, const std::string& solver, const SolverSettings& settings) {
  const auto t0 = std::chrono::steady_clock::now();
  std::lock_guard device(device_mutex_);
  const TransferFunction ref_tf = ref_tf_in;  // a copy: install() replaces the member it may refer to
  OptimizeResult r = run_optimization(ref_, field_, ref_tf, solver, settings);
  auto derived = derive(ref_, field_, ref_tf, r, derived_.get());
  nlohmann::json summary = job_summary(r);
  install(std::nullopt, ref_tf, std::move(r), std::move(derived), solver, settings);
  finish_job(summary, t0);
}

nlohmann::json ViewSession::job_summary(const OptimizeResult& r) {
  return {{"solver", r.solver},
          {"voxel_rmse_reference_tf", r.before.rmse()},
          {"voxel_rmse_optimized_tf", r.after.rmse()},
          {"warnings", r.warnings}};
}

void ViewSession::finish_job(nlohmann::json summary, std::chrono::steady_clock::time_point start) {
  summary["ms"] = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  std::lock_guard status(job_mutex_);
  job_.result = std::move(summary);
}

uint64_t ViewSession::set_reference_tf(const ControlPointTf& points, bool reoptimize) {
  TransferFunction table;
  {
    std::lock_guard data(data_mutex_);
    table = table_from_control_points(points, ref_tf_.size());
    table.range = ref_tf_.range;
  }
  if (reoptimize) {
    std::string solver;
    SolverSettings settings;
    {
      std::lock_guard data(data_mutex_);
      solver = solver_;
      settings = solver_settings_;
    }
    return start_job("optimize", [this, table, solver, settings] { optimize_job(table, solver, settings); });
  }
  // The optimized TF stays; what depends on the reference TF follows: both voxel losses (one pass
  // for both) and the residual maps.
  if (job_running_) throw ConflictError("a job is running: apply the reference TF when it ends");
  std::unique_lock device = lock_device_for_request();
  OptimizeResult r = result_;
  auto derived = derive(ref_, field_, table, r, derived_.get());
  const VoxelLosses losses = voxel_losses_gpu(ctx_, *derived->ref, *derived->field, derived->ref_map,
                                              derived->field_ref_map, derived->field_opt_map, *derived->ref_tf,
                                              *derived->opt_tf);
  r.before = losses.before;
  r.after = losses.after;
  install(std::nullopt, table, std::move(r), std::move(derived), solver_, solver_settings_);
  return 0;
}

uint64_t ViewSession::set_point(const GridIndex& point) {
  if (!ensemble_) throw ConflictError("a reference point applies to ensemble mode (tfmatch view --ensemble)");
  const Volume& grid = ensemble_->ensemble.grid;
  for (int k = 0; k < 3; ++k)
    if (point[size_t(k)] >= grid.dims[size_t(k)])
      throw std::invalid_argument("reference point (" + std::to_string(point[0]) + ", " + std::to_string(point[1]) +
                                  ", " + std::to_string(point[2]) + ") is outside the grid");
  const uint64_t voxel = linear_index(grid, point);
  check_reference_point(ensemble_->ensemble.view(), voxel, ensemble_->params.measure);
  check_reference_point(ensemble_->ensemble.view(), voxel, ensemble_->versus);
  return start_job("point", [this, point] {
    const auto t0 = std::chrono::steady_clock::now();
    std::lock_guard device(device_mutex_);
    std::pair<Volume, Volume> fields = correlation_fields(point);
    std::string solver;
    SolverSettings settings;
    {
      std::lock_guard data(data_mutex_);
      solver = solver_;
      settings = solver_settings_;
    }
    OptimizeResult r = run_optimization(fields.first, fields.second, ref_tf_, solver, settings);
    auto derived = derive(fields.first, fields.second, ref_tf_, r);
    nlohmann::json summary = job_summary(r);
    summary["point"] = point;
    {
      std::lock_guard data(data_mutex_);
      ensemble_->point = point;
    }
    install(std::move(fields), ref_tf_, std::move(r), std::move(derived), solver, settings);
    finish_job(summary, t0);
  });
}

uint64_t ViewSession::set_field(size_t index) {
  if (!series_) throw ConflictError("choosing a field applies to series mode (tfmatch view with several --field)");
  if (index >= series_->labels.size())
    throw std::invalid_argument("field " + std::to_string(index) + " of a series of " +
                                std::to_string(series_->labels.size()) + " (0 to " +
                                std::to_string(series_->labels.size() - 1) + ")");
  return start_job("field", [this, index] {
    const auto t0 = std::chrono::steady_clock::now();
    std::lock_guard device(device_mutex_);
    Volume field = series_->load(index);
    require_same_grid(ref_, field);
    std::string solver;
    SolverSettings settings;
    {
      std::lock_guard data(data_mutex_);
      solver = solver_;
      settings = solver_settings_;
    }
    OptimizeResult r = run_optimization(ref_, field, ref_tf_, solver, settings);
    auto derived = derive(ref_, field, ref_tf_, r);
    nlohmann::json summary = job_summary(r);
    summary["field"] = index;
    {
      std::lock_guard data(data_mutex_);  // the new field with its result just below (a job runs meanwhile)
      series_->index = index;
      // Swapped, not assigned: the old field's values stay alive (in `field`) until install() has
      // released the state whose device fields may read them in place.
      std::swap(field_, field);
    }
    install(std::nullopt, ref_tf_, std::move(r), std::move(derived), solver, settings);
    finish_job(summary, t0);
  });
}

void ViewSession::wait_for_job() {
  // Not under job_mutex_ while the job runs: its progress and its end take that lock.
  while (job_running_) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::lock_guard lock(job_mutex_);  // the thread has ended its work; no new job starts meanwhile
  if (job_thread_.joinable()) job_thread_.join();
}

nlohmann::json ViewSession::job() const {
  std::lock_guard lock(job_mutex_);
  const auto end = job_.state == "running" ? std::chrono::steady_clock::now() : job_.end;
  nlohmann::json j = {{"id", job_.id},
                      {"kind", job_.kind},
                      {"state", job_.state},
                      {"label", job_.label},
                      {"done", job_.done},
                      {"total", job_.total},
                      {"elapsed_s", job_.id ? std::chrono::duration<double>(end - job_.start).count() : 0.0},
                      {"error", job_.error},
                      {"result", job_.result}};
  return j;
}

// ---- state and downloads ----------------------------------------------------------------------

nlohmann::json ViewSession::render_commands() const {
  const RenderSettings& s = config_.render;
  std::string common = " --step " + short_number(s.step_voxels) + " --opacity-scale " + short_number(s.opacity_scale) +
                       " --z-scale " + short_number(s.z_scale) + " --termination " + short_number(s.termination_opacity) +
                       " --background '" + hex_color(linear_to_srgb(Rgb{s.background[0], s.background[1], s.background[2]})) +
                       "'";
  if (!s.box_outline) common += " --no-outline";
  for (const GridIndex& m : markers())
    common += " --marker " + std::to_string(m[0]) + "," + std::to_string(m[1]) + "," + std::to_string(m[2]);
  auto command = [&](const char* volume, const char* tf, const FieldRange& range) {
    return std::string("tfmatch render --volume ") + volume + " --tf " + tf + " --range " + exact_number(range.lo) +
           "," + exact_number(range.hi) + common;
  };
  const Derived& d = *derived_;
  return {{"reference", command("reference.vti", "reference-tf.json", result_.ref_range)},
          {"field-ref-tf", command("field.vti", "reference-tf.json", result_.field_range)},
          {"field-opt-tf", command("field.vti", "optimized-tf.json", result_.field_range)},
          {"residual", command("residual.vti", "residual-tf.json", d.res_range)}};
}

nlohmann::json ViewSession::state() const {
  std::lock_guard data(data_mutex_);
  const RenderSettings& s = config_.render;
  nlohmann::json axes = nlohmann::json::array();
  static const char* kAxisNames[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k) {
    const GridAxis& a = ref_.axes[size_t(k)];
    // The first and last index's coordinates: the page labels slice axes with them.
    axes.push_back({{"name", a.name.empty() ? kAxisNames[k] : a.name},
                    {"units", a.units},
                    {"first", axis_coordinate(ref_, k, 0)},
                    {"last", axis_coordinate(ref_, k, ref_.dims[size_t(k)] - 1)}});
  }
  nlohmann::json extra = nlohmann::json::object();
  for (const auto& [k, v] : solver_settings_.extra) extra[k] = v;
  nlohmann::json state = {
      {"mode", ensemble_ ? "ensemble" : series_ ? "series" : "pair"},
      {"title", config_.title},
      {"version", version_},
      {"fields",
       {{"reference", {{"name", ref_.name}, {"range", range_json(result_.ref_range)}}},
        {"field", {{"name", field_.name}, {"range", range_json(result_.field_range)}}}}},
      {"grid", {{"dims", ref_.dims}, {"axes", axes}}},
      {"ref_tf", {{"size", ref_tf_.size()}, {"points", editor_points_json(editor_points(ref_tf_))}}},
      {"optimized_tf", {{"size", result_.tf.size()}, {"solver", result_.solver}}},
      {"render",
       {{"width", s.width},
        {"height", s.height},
        {"step_voxels", s.step_voxels},
        {"opacity_scale", s.opacity_scale},
        {"z_scale", s.z_scale},
        {"background", hex_color(linear_to_srgb(Rgb{s.background[0], s.background[1], s.background[2]}))},
        {"camera",
         {{"azimuth_deg", s.camera.azimuth_deg},
          {"elevation_deg", s.camera.elevation_deg},
          {"distance", s.camera.distance},
          {"fov_deg", s.camera.fov_deg}}}}},
      {"render_commands", render_commands()},
      {"limits", {{"max_image_side", 2048}, {"max_slice_size", 1024}}},
      {"solvers", solvers_json()},
      {"solver",
       {{"name", solver_},
        {"options", extra},
        {"ridge", solver_settings_.solve.ridge},
        {"smooth", solver_settings_.solve.smooth}}},
      {"metrics",
       {{"voxel_rmse_reference_tf", result_.before.rmse()},
        {"voxel_rmse_optimized_tf", result_.after.rmse()},
        {"voxels_with_data", result_.after.voxels},
        {"residual_max", derived_->res_range.hi}}},
      {"warnings", result_.warnings},
      {"ensemble", nullptr},
      {"series", nullptr},
      {"markers", markers()},
  };
  state["render_command"] = state["render_commands"]["reference"];
  if (ensemble_) {
    const ViewEnsemble& e = *ensemble_;
    state["ensemble"] = {{"measure", correlation_measure_name(e.params.measure)},
                         {"versus", correlation_measure_name(e.versus)},
                         {"members", e.ensemble.member_count},
                         {"point", e.point},
                         {"point_text", describe_grid_point(e.ensemble.grid, e.point)}};
  }
  if (series_)
    state["series"] = {{"count", series_->labels.size()}, {"index", series_->index}, {"labels", series_->labels}};
  state["job"] = job();
  return state;
}

ViewSession::Download ViewSession::download(std::string_view what) const {
  std::lock_guard data(data_mutex_);
  const Derived& d = *derived_;
  const std::string name(what);
  const std::string json = "application/json", vti = "application/octet-stream";
  if (what == "optimized-tf.json") return {tf_to_json(result_.tf), name, json};
  if (what == "optimized-tf.paraview.json") return {tf_to_paraview_json(result_.tf, "tfmatch optimized TF"), name, json};
  if (what == "reference-tf.json") return {tf_to_json(ref_tf_), name, json};
  if (what == "residual-tf.json") return {tf_to_json(d.res_tf_table), name, json};
  if (what == "residual.vti") return {vti_bytes({{"residual", &d.res_after}}, name), name, vti};
  if (what == "reference.vti") return {vti_bytes({{"reference", &ref_}}, name), name, vti};
  if (what == "field.vti") return {vti_bytes({{"field", &field_}}, name), name, vti};
  throw std::invalid_argument("unknown download \"" + name +
                              "\": optimized-tf.json, optimized-tf.paraview.json, reference-tf.json, "
                              "residual-tf.json, residual.vti, reference.vti or field.vti");
}

}  // namespace tfm
