// The viewer session's device requests: renderings, image metrics, slices and TF plots.
#include <algorithm>
#include <chrono>

#include "tfmatch/kernels/residual.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/report/tf_plot.h"
#include "tfmatch/viewer/view_session.h"
#include "tfmatch/viewer/view_session_derived.h"

namespace tfm {

// ---- device requests ----------------------------------------------------------------------------

std::unique_lock<std::mutex> ViewSession::lock_device_for_request() {
  if (job_running_) throw BusyError("the device is busy with a job; try again when it ends");
  std::unique_lock lock(device_mutex_);
  return lock;
}

std::vector<GridIndex> ViewSession::markers() const {
  if (ensemble_) return {ensemble_->point};
  return config_.markers;
}

namespace {

double ms_between(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// Whether two settings render the same picture (the outline is drawn afterwards).
bool same_rendering(const RenderSettings& a, const RenderSettings& b) {
  return a.width == b.width && a.height == b.height && a.step_voxels == b.step_voxels &&
         a.opacity_scale == b.opacity_scale && a.background == b.background &&
         a.termination_opacity == b.termination_opacity && a.z_scale == b.z_scale &&
         a.camera.azimuth_deg == b.camera.azimuth_deg && a.camera.elevation_deg == b.camera.elevation_deg &&
         a.camera.distance == b.camera.distance && a.camera.fov_deg == b.camera.fov_deg;
}

// The picture of a rendering: over the background in 8-bit sRGB, with the box outline and the
// markers when decorated (`undecorated`, when given, receives the picture before). Needs no
// device: render() does it after letting the device go, so it overlaps the next request's render.
Image finish_picture(const RenderedImage& rendered, const RenderSettings& s, const VolumeGeometry& geometry,
                     const std::array<GridAxis, 3>& axes, const std::vector<GridIndex>& markers, bool decorate,
                     PictureTiming* timing, Image* undecorated = nullptr) {
  const auto t0 = std::chrono::steady_clock::now();
  Image picture = composite_over(rendered, s.background);
  if (undecorated) *undecorated = picture;
  const auto t1 = std::chrono::steady_clock::now();
  if (decorate) {
    draw_box_outline(picture, geometry, s, &axes, markers);
    draw_markers(picture, geometry, s, markers);
  }
  if (timing) {
    timing->compose_ms = ms_between(t0, t1);
    timing->decorate_ms = ms_between(t1, std::chrono::steady_clock::now());
  }
  return picture;
}

}  // namespace

RenderedImage ViewSession::render_on_device(ViewKind view, RenderSettings& s, PictureTiming* timing) {
  s.z_scale = config_.render.z_scale;  // the renderers' geometry
  validate(s);
  check_render_size(ctx_, s);
  const Derived& d = *derived_;
  const GpuRenderer* renderer = nullptr;
  const FieldMapping* map = nullptr;
  const Buffer* tf = nullptr;
  switch (view) {
    case ViewKind::Reference: renderer = d.ref_renderer.get(), map = &d.ref_map, tf = &*d.ref_tf; break;
    case ViewKind::FieldRefTf: renderer = d.field_renderer.get(), map = &d.field_ref_map, tf = &*d.ref_tf; break;
    case ViewKind::FieldOptTf: renderer = d.field_renderer.get(), map = &d.field_opt_map, tf = &*d.opt_tf; break;
    case ViewKind::Residual: renderer = d.res_after_renderer.get(), map = &d.res_map, tf = &*d.res_tf; break;
    case ViewKind::ResidualBefore: renderer = d.res_before_renderer.get(), map = &d.res_map, tf = &*d.res_tf; break;
  }
  RenderCallTimes times;
  RenderedImage rendered = renderer->render_colours(*map, *tf, s, &times);
  if (timing) {
    timing->render_ms = times.dispatch_ms;
    timing->readback_ms = times.readback_ms;
  }
  return rendered;
}

Image ViewSession::render_picture(ViewKind view, const RenderSettings& settings, bool decorate) {
  RenderSettings s = settings;
  const RenderedImage rendered = render_on_device(view, s, nullptr);
  return finish_picture(rendered, s, derived_->geometry, derived_->axes, markers(), decorate, nullptr);
}

Image ViewSession::render(ViewKind view, const RenderSettings& settings, double* distance_used, PictureTiming* timing,
                          const std::function<bool()>& wanted) {
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_lock device = lock_device_for_request();
  if (timing) timing->wait_ms = ms_between(t0, std::chrono::steady_clock::now());
  if (wanted && !wanted()) throw SupersededError("a newer camera from the same client replaced this picture");
  RenderSettings s = settings;
  const RenderedImage rendered = render_on_device(view, s, timing);
  // What the picture needs of the session's state, copied while the device (and so the state a
  // job would replace) is still this request's.
  const VolumeGeometry geometry = derived_->geometry;
  const std::array<GridAxis, 3> axes = derived_->axes;
  const std::vector<GridIndex> dots = markers();
  const uint64_t version = version_;
  device.unlock();
  if (distance_used) {
    const CameraFrame frame = orbit_frame(s.camera, geometry, s.width, s.height);
    *distance_used = glm::length(frame.eye - geometry.center()) / geometry.radius();
  }
  Shown shown{version, s, {}};
  Image picture = finish_picture(rendered, s, geometry, axes, dots, true, timing, &shown.picture);
  keep_shown(view, std::move(shown));
  return picture;
}

void ViewSession::keep_shown(ViewKind view, Shown shown) {
  std::lock_guard lock(shown_mutex_);
  std::vector<Shown>& kept = shown_[size_t(view)];
  // A picture of an older state (a job installed meanwhile) is never kept beside newer ones; a
  // newer state's picture ends the older ones.
  if (!kept.empty() && shown.version < kept.front().version) return;
  std::erase_if(kept, [&](const Shown& k) { return k.version < shown.version || same_rendering(k.settings, shown.settings); });
  kept.insert(kept.begin(), std::move(shown));
  size_t bytes = 0, keep = 0;
  while (keep < kept.size() && keep < kShownPerView &&
         (keep == 0 || bytes + kept[keep].picture.rgb.size() <= kShownBytesPerView))
    bytes += kept[keep++].picture.rgb.size();
  kept.resize(keep);
}

nlohmann::json ViewSession::image_metrics(const RenderSettings& settings, const std::function<bool()>& wanted) {
  std::unique_lock device = lock_device_for_request();
  // Asked before each of the three renders: a page that moves the camera meanwhile waits for at
  // most one of them, not all three, before its new pictures start.
  RenderSettings s = settings;
  s.z_scale = config_.render.z_scale;  // as render_on_device sets it
  int rendered = 0;
  if (wanted && !wanted()) throw SupersededError("a newer camera from the same client replaced these metrics");
  auto picture = [&](ViewKind view) {
    {
      std::lock_guard lock(shown_mutex_);
      for (const Shown& shown : shown_[size_t(view)])
        if (shown.version == version_ && same_rendering(shown.settings, s)) return shown.picture;
    }
    if (wanted && !wanted()) throw SupersededError("a newer camera from the same client replaced these metrics");
    ++rendered;
    return render_picture(view, settings, false);
  };
  const Image ref = picture(ViewKind::Reference);
  const Image before = picture(ViewKind::FieldRefTf);
  const Image after = picture(ViewKind::FieldOptTf);
  return {{"reference_tf", compare_images(ref, before).to_json()},
          {"optimized_tf", compare_images(ref, after).to_json()},
          {"rendered", rendered}};
}

Image ViewSession::slice(ViewKind view, int axis, uint64_t index, uint32_t max_size, SliceShading shading) {
  std::unique_lock device = lock_device_for_request();
  const Derived& d = *derived_;
  SliceStyle style;
  style.background = config_.render.background;
  style.z_scale = config_.render.z_scale;
  style.max_size = max_size;
  style.shading = shading;
  style.opacity_scale = max_opacity(ref_tf_);  // one scale for the three classified fields (as the report)
  SliceStyle res_style = style;
  res_style.opacity_scale = max_opacity(d.res_tf_table);
  // The view's field, TF, range and style: one of the three classified fields or a residual map.
  auto picture = [&](const Volume& v, const TransferFunction& tf, const FieldRange& range, const SliceStyle& st) {
    const SliceValues values = extract_slice(v, axis, index);
    Image image = slice_image(v, values, tf, range, st);
    mark_slice(image, values, {}, markers());  // as on the renderings: red dots where they lie in the plane
    return image;
  };
  switch (view) {
    case ViewKind::Reference:
      return picture(ref_, ref_tf_, result_.ref_range, style);
    case ViewKind::FieldRefTf:
      return picture(field_, ref_tf_, result_.field_range, style);
    case ViewKind::FieldOptTf:
      return picture(field_, result_.tf, result_.field_range, style);
    case ViewKind::Residual:
      return picture(d.res_after, d.res_tf_table, d.res_range, res_style);
    case ViewKind::ResidualBefore:
      return picture(d.res_before, d.res_tf_table, d.res_range, res_style);
  }
  throw std::invalid_argument("unknown view");
}

Image ViewSession::tf_plot(ViewKind view, uint32_t width, uint32_t height, bool log_counts) {
  std::unique_lock device = lock_device_for_request();
  const Derived& d = *derived_;
  TfPlotOptions plot;
  plot.width = width;
  plot.height = height;
  plot.log_counts = log_counts;
  switch (view) {
    case ViewKind::Reference:
      plot.title = "Reference TF, reference field histogram";
      plot.axis_label = ref_.name;
      return plot_transfer_function(ref_tf_, ref_.values, result_.ref_range, plot);
    case ViewKind::FieldRefTf:
      plot.title = "Reference TF, field histogram";
      plot.axis_label = field_.name;
      return plot_transfer_function(ref_tf_, field_.values, result_.field_range, plot);
    case ViewKind::FieldOptTf:
      plot.title = "Optimized TF (" + result_.solver + "), field histogram";
      plot.axis_label = field_.name;
      return plot_transfer_function(result_.tf, field_.values, result_.field_range, plot);
    case ViewKind::Residual:
    case ViewKind::ResidualBefore:
      plot.title = view == ViewKind::Residual ? "Residual TF, histogram after" : "Residual TF, histogram before";
      plot.axis_label = kResidualValueLabel;
      return plot_transfer_function(d.res_tf_table, (view == ViewKind::Residual ? d.res_after : d.res_before).values,
                                    d.res_range, plot);
  }
  throw std::invalid_argument("unknown view");
}

}  // namespace tfm
