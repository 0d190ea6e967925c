// The viewer session's device requests: renderings, image metrics, slices and TF plots.
#include <algorithm>
#include <chrono>

#include "camera.h"
#include "metrics.h"
#include "tf_plot.h"
#include "view_session.h"
#include "view_session_derived.h"

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

Image ViewSession::render_picture(ViewKind view, const RenderSettings& s_in, bool decorate, double* distance_used) {
  RenderSettings s = s_in;
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
  Image picture = composite_over(renderer->render(*map, *tf, s), s.background);
  if (decorate) {
    draw_box_outline(picture, d.geometry, s);
    draw_markers(picture, d.geometry, s, markers());
  }
  if (distance_used) {
    const CameraFrame frame = orbit_frame(s.camera, d.geometry, s.width, s.height);
    *distance_used = glm::length(frame.eye - d.geometry.center()) / d.geometry.radius();
  }
  return picture;
}

Image ViewSession::render(ViewKind view, const RenderSettings& settings, double* distance_used, double* render_ms) {
  std::unique_lock device = lock_device_for_request();
  const auto t0 = std::chrono::steady_clock::now();
  Image picture = render_picture(view, settings, true, distance_used);
  if (render_ms) *render_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return picture;
}

nlohmann::json ViewSession::image_metrics(const RenderSettings& settings) {
  std::unique_lock device = lock_device_for_request();
  const Image ref = render_picture(ViewKind::Reference, settings, false, nullptr);
  const Image before = render_picture(ViewKind::FieldRefTf, settings, false, nullptr);
  const Image after = render_picture(ViewKind::FieldOptTf, settings, false, nullptr);
  return {{"reference_tf", compare_images(ref, before).to_json()},
          {"optimized_tf", compare_images(ref, after).to_json()}};
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
  switch (view) {
    case ViewKind::Reference:
      return slice_image(ref_, extract_slice(ref_, axis, index), ref_tf_, result_.ref_range, style);
    case ViewKind::FieldRefTf:
      return slice_image(field_, extract_slice(field_, axis, index), ref_tf_, result_.field_range, style);
    case ViewKind::FieldOptTf:
      return slice_image(field_, extract_slice(field_, axis, index), result_.tf, result_.field_range, style);
    case ViewKind::Residual:
      return slice_image(d.res_after, extract_slice(d.res_after, axis, index), d.res_tf_table, d.res_range, res_style);
    case ViewKind::ResidualBefore:
      return slice_image(d.res_before, extract_slice(d.res_before, axis, index), d.res_tf_table, d.res_range,
                         res_style);
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
      plot.axis_label = "residual (RGBA distance)";
      return plot_transfer_function(d.res_tf_table, (view == ViewKind::Residual ? d.res_after : d.res_before).values,
                                    d.res_range, plot);
  }
  throw std::invalid_argument("unknown view");
}

}  // namespace tfm
