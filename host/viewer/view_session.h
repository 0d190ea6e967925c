// What `tfmatch view` shows and changes, independent of HTTP: both fields kept on the device with
// the reference, optimized and residual TFs, renderings, slices and plots of the four quantities,
// and the jobs that change them (an optimization, a new reference TF, a new reference point of an
// ensemble), run one at a time on a thread of their own with their progress observable.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/ensemble.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/slice.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/solvers/optimize.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

// The four quantities of the page (and the residual with the reference TF).
enum class ViewKind { Reference, FieldRefTf, FieldOptTf, Residual, ResidualBefore };
// "reference", "field-ref-tf", "field-opt-tf", "residual", "residual-before"; nullopt otherwise.
std::optional<ViewKind> parse_view_kind(std::string_view name);
const char* view_kind_name(ViewKind view);

// A device request made while a job holds the device (HTTP 503: try again shortly).
class BusyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A picture whose client has asked for a newer camera while it waited for the device: dropped,
// not rendered (HTTP 410).
class SupersededError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A request that cannot apply now or here: a job runs, or ensemble-only in pair mode (HTTP 409).
class ConflictError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Where a picture's time went (GET /api/render's Server-Timing header), milliseconds.
struct PictureTiming {
  double wait_ms = 0.0;      // for the device: requests are served one at a time
  double render_ms = 0.0;    // recording, submitting and waiting for the render
  double readback_ms = 0.0;  // the image back to the host
  double compose_ms = 0.0;   // over the background, to 8-bit sRGB
  double decorate_ms = 0.0;  // box outline and markers
  double picture_ms() const { return render_ms + readback_ms + compose_ms + decorate_ms; }
};

// An ensemble and the two measures compared (ensemble mode): the reference field is `measure`'s
// correlation field of `point`, the second field `versus`'s.
struct ViewEnsemble {
  Ensemble ensemble;
  CorrelationParams params;  // params.measure: the reference's measure; bins and k for both
  CorrelationMeasure versus = CorrelationMeasure::Pearson;
  GridIndex point{};
};

// Many fields against one reference (series mode): one field shown at a time, its TF fitted
// when it is chosen.
struct ViewSeries {
  std::vector<std::string> labels;             // one per field, as the user named it
  std::function<Volume(size_t)> load;          // field i, loaded when chosen
  size_t index = 0;                            // the field shown
};

struct ViewConfig {
  std::string title = "tfmatch view";
  TransferFunction ref_tf;                            // linear RGB table; its range as a TF file's
  std::optional<FieldRange> ref_range, field_range;  // user ranges (run_optimize's defaults otherwise)
  uint32_t tf_size = 64;                              // entries of the optimized TF
  bool allow_out_of_range = false;
  std::string solver = "normal-equations";            // the first optimization's
  SolverSettings solver_settings;
  RenderSettings render;                              // the default camera and the optical model
  std::vector<GridIndex> markers;                     // pair mode: red dots on the renderings
};

class ViewSession {
 public:
  // Pair mode. Uploads both fields and runs the first optimization before returning. Throws
  // std::runtime_error as run_optimize does (grids differ, constant field, bad solver option).
  ViewSession(Context& ctx, Volume ref, Volume field, ViewConfig config);
  // Ensemble mode: both correlation fields of ensemble.point, then the first optimization.
  // Throws std::invalid_argument for a point that cannot be a reference point.
  ViewSession(Context& ctx, ViewEnsemble ensemble, ViewConfig config);
  // Series mode: the reference and field series.index, optimized before returning. Throws as
  // pair mode does, std::invalid_argument for no fields or an index past them.
  ViewSession(Context& ctx, Volume ref, ViewSeries series, ViewConfig config);
  ~ViewSession();  // waits for a running job
  ViewSession(const ViewSession&) = delete;
  ViewSession& operator=(const ViewSession&) = delete;

  // The page's state (host/viewer/http_api.md, GET /api/state).
  nlohmann::json state() const;
  // The current or last job (GET /api/job).
  nlohmann::json job() const;
  bool job_running() const { return job_running_; }
  // Increases whenever a TF or a field changes (state()["version"]).
  uint64_t version() const {
    std::lock_guard data(data_mutex_);
    return version_;
  }
  const RenderSettings& default_render() const { return config_.render; }
  const Volume& grid() const { return ref_; }  // dims, spacing, axes (fixed for the session)

  // ---- device requests: each throws BusyError while a job runs, std::runtime_error for
  // settings the device cannot render (render.h check_render_size) ----
  // The picture `tfmatch render` makes of the view's field and TF with `settings` (sRGB, box
  // outline, markers). `distance_used` receives the camera distance in bounding-sphere radii
  // (the framed one when settings.camera.distance is 0); `timing` where the time went. With
  // `wanted`, asked once the device is this request's: false throws SupersededError instead of
  // rendering (a camera the client has moved past).
  Image render(ViewKind view, const RenderSettings& settings, double* distance_used = nullptr,
               PictureTiming* timing = nullptr, const std::function<bool()>& wanted = {});
  // Image RMSE / PSNR / SSIM of the field with each TF against the reference at `settings`
  // (`wanted` as for render), and "rendered": how many of the three pictures it rendered. A
  // picture render() made last for the same view, settings and state is used as it is (the page
  // asks for the metrics right after showing the pictures of the same camera, so they usually
  // cost no rendering at all).
  nlohmann::json image_metrics(const RenderSettings& settings, const std::function<bool()>& wanted = {});
  // Plane `index` of `axis` (0..2) classified by the view's TF (slice.h): its colours at full
  // strength, or over the background by opacity, and markers() in the plane as red dots (slice.h
  // mark_slice). Throws std::invalid_argument for an axis or index outside the grid.
  Image slice(ViewKind view, int axis, uint64_t index, uint32_t max_size,
              SliceShading shading = SliceShading::Colour);
  // The view's TF over its field's histogram (tf_plot.h).
  Image tf_plot(ViewKind view, uint32_t width, uint32_t height, bool log_counts);

  // ---- jobs: one at a time; each throws ConflictError while another runs ----
  // Optimizes again with `solver` and `settings` (their options checked first: std::runtime_error
  // naming a bad or inapplicable one). Returns the job id.
  uint64_t optimize(const std::string& solver, const SolverSettings& settings);
  // Replaces the reference TF by the table of `points` (the current table's size and range).
  // With `reoptimize`, the current solver runs again as a job whose id is returned; otherwise the
  // losses and residual maps follow at once and 0 is returned.
  uint64_t set_reference_tf(const ControlPointTf& points, bool reoptimize);
  // Ensemble mode: a new reference point; both fields are computed again and the TF optimized
  // again, as a job. Throws ConflictError in pair mode, std::invalid_argument for a point outside
  // the grid or one that cannot be a reference point (no data, a constant series).
  uint64_t set_point(const GridIndex& point);
  // Series mode: show field `index` (loaded, its TF fitted with the current solver) as a job.
  // Throws ConflictError in the other modes, std::invalid_argument for an index past the fields.
  uint64_t set_field(size_t index);
  // Blocks until no job runs (tests, shutdown).
  void wait_for_job();

  struct Download {
    std::string bytes, filename, content_type;
  };
  // "optimized-tf.json", "optimized-tf.paraview.json", "reference-tf.json", "residual-tf.json",
  // "residual.vti", "reference.vti", "field.vti". Throws std::invalid_argument for other names.
  Download download(std::string_view what) const;

 private:
  struct Derived;  // device fields, TF buffers, renderers, residual maps
  struct JobStatus {
    uint64_t id = 0;
    std::string kind, state = "idle", label, error;
    uint64_t done = 0, total = 0;
    std::chrono::steady_clock::time_point start, end;
    nlohmann::json result;
  };

  void initialize();
  OptimizeResult run_optimization(const Volume& ref, const Volume& field, const TransferFunction& ref_tf,
                                  const std::string& solver, const SolverSettings& settings);
  // `same_fields`: the current Derived when ref and field are unchanged (its device copies and
  // renderers are shared instead of uploaded again); nullptr for new fields.
  std::unique_ptr<Derived> derive(const Volume& ref, const Volume& field, const TransferFunction& ref_tf,
                                  const OptimizeResult& result, const Derived* same_fields = nullptr);
  void install(std::optional<std::pair<Volume, Volume>> fields, TransferFunction ref_tf, OptimizeResult result,
               std::unique_ptr<Derived> derived, const std::string& solver, const SolverSettings& settings);
  std::pair<Volume, Volume> correlation_fields(const GridIndex& point);
  // The body of an optimization job: optimize with `ref_tf`, derive, install, record the result.
  void optimize_job(const TransferFunction& ref_tf, const std::string& solver, const SolverSettings& settings);
  static nlohmann::json job_summary(const OptimizeResult& result);
  void finish_job(nlohmann::json summary, std::chrono::steady_clock::time_point start);
  uint64_t start_job(const std::string& kind, std::function<void()> work);
  std::unique_lock<std::mutex> lock_device_for_request();
  // Under device_mutex_: the rendering of `settings` (its z scale set to the session's).
  RenderedImage render_on_device(ViewKind view, RenderSettings& settings, PictureTiming* timing);
  Image render_picture(ViewKind view, const RenderSettings& settings, bool decorate);
  std::vector<GridIndex> markers() const;
  nlohmann::json render_commands() const;

  Context& ctx_;
  ViewConfig config_;
  std::optional<ViewEnsemble> ensemble_;
  std::optional<ViewSeries> series_;

  // Lock order: device_mutex_ before data_mutex_. The device and everything on it (Derived) are
  // used only under device_mutex_; what state() and downloads read is written only under both,
  // so either one suffices to read it.
  mutable std::mutex device_mutex_;
  mutable std::mutex data_mutex_;
  Volume ref_, field_;
  TransferFunction ref_tf_;
  OptimizeResult result_;
  std::unique_ptr<Derived> derived_;
  std::string solver_;
  SolverSettings solver_settings_;
  uint64_t version_ = 0;

  // The last pictures render() made of each view, before decoration, for image_metrics: the
  // state's version and the settings each was rendered with (z scale the session's). A few per
  // view, so that pages at different cameras (two tabs, two people) each find their own pictures
  // when they ask for the metrics; newest first, at most kShownPerView and kShownBytesPerView
  // (the newest always kept).
  struct Shown {
    uint64_t version = 0;
    RenderSettings settings;
    Image picture;
  };
  static constexpr size_t kShownPerView = 4;
  static constexpr size_t kShownBytesPerView = size_t(16) << 20;
  void keep_shown(ViewKind view, Shown shown);
  mutable std::mutex shown_mutex_;
  std::array<std::vector<Shown>, 5> shown_;  // by ViewKind

  mutable std::mutex job_mutex_;
  JobStatus job_;
  std::atomic<bool> job_running_{false};
  std::thread job_thread_;
};

}  // namespace tfm
