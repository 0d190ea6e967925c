// Rendering fields on the device: a renderer bound to one device field, and one-call helpers
// that upload a volume and its TF, render with RenderSettings and read the image back.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// Wall-clock time of a GpuRenderer::render call's parts, milliseconds.
struct RenderCallTimes {
  double dispatch_ms = 0.0;  // recording, submitting and waiting for the render and its copy to host-visible memory
  double readback_ms = 0.0;  // the image out of that memory into the RenderedImage
};

class GpuRenderer {
 public:
  // The pipeline is specialized for the field's chunk count. Throws std::runtime_error when the
  // field has more chunks than the renderer binds.
  GpuRenderer(Context& ctx, const DeviceField& field, const VolumeGeometry& geometry);
  ~GpuRenderer();
  GpuRenderer(const GpuRenderer&) = delete;
  GpuRenderer& operator=(const GpuRenderer&) = delete;

  // Renders settings.camera. With `progress`, the image is rendered in bands of rows, one
  // submission each, and progress->update(rows done) after each; otherwise in one dispatch.
  // `gpu_ms` receives the GPU time (sum over bands; -1 without timestamps), `times` the wall
  // time of the dispatch (the copy to host-visible memory included: one submission) and of the
  // copy out of it. Calls from several threads take turns (the renderer keeps its buffers).
  RenderedImage render(const FieldMapping& mapping, const Buffer& tf, const RenderSettings& settings,
                       Progress* progress = nullptr, double* gpu_ms = nullptr, RenderCallTimes* times = nullptr) const;
  // The colours only (RenderedImage::stop left empty), in one dispatch: what a picture needs,
  // without reading back the stop indices DiffDVR uses.
  RenderedImage render_colours(const FieldMapping& mapping, const Buffer& tf, const RenderSettings& settings,
                               RenderCallTimes* times = nullptr) const;

 private:
  RenderedImage render_impl(const FieldMapping& mapping, const Buffer& tf, const RenderSettings& settings,
                            Progress* progress, double* gpu_ms, RenderCallTimes* times, bool read_stop) const;
  Context& ctx_;
  const DeviceField& field_;
  VolumeGeometry geometry_;
  RenderImageKernel kernel_;
  struct Scratch;
  std::unique_ptr<Scratch> scratch_;  // buffers kept between calls
};

// Throws std::runtime_error, before anything is allocated, when a settings.width x
// settings.height image cannot be rendered here: its image buffer (16 bytes a pixel) must fit the
// device's largest storage buffer (maxStorageBufferRange) and its memory heap, and the image read
// back (20 bytes a pixel) must fit the memory budget (memory_budget.h). The message names the
// largest square image that fits. GpuRenderer::render calls it; commands call it up front.
void check_render_size(const Context& ctx, const RenderSettings& settings);

// Draws each grid point of `markers` (voxel indices) as a red dot where the camera of
// `settings` sees it on an image of the same size (the paper's reference-point markers). The
// dots are drawn over the rendering, visible from every side.
void draw_markers(Image& image, const VolumeGeometry& geometry, const RenderSettings& settings,
                  const std::vector<std::array<uint64_t, 3>>& markers);

// Uploads `volume` and `tf` and renders them; `range` maps the field to the TF.
RenderedImage render_volume(Context& ctx, const Volume& volume, const TransferFunction& tf, const FieldRange& range,
                            const RenderSettings& settings, Progress* progress = nullptr);

}  // namespace tfm
