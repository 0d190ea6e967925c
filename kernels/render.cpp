// GPU rendering of a device field into a host image.
#include "tfmatch/kernels/render.h"

#include <chrono>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {

void check_render_size(const Context& ctx, const RenderSettings& s) {
  const uint64_t pixels = uint64_t(s.width) * s.height;
  const uint64_t image_bytes = pixels * 16;  // RGBA float32 on the device
  uint64_t largest_heap = 0;
  const VkPhysicalDeviceMemoryProperties& mem = ctx.memory_properties();
  for (uint32_t i = 0; i < mem.memoryHeapCount; ++i) largest_heap = std::max<uint64_t>(largest_heap, mem.memoryHeaps[i].size);
  const uint64_t device_limit = std::min<uint64_t>(ctx.limits().maxStorageBufferRange, largest_heap);
  const std::string size = std::to_string(s.width) + "x" + std::to_string(s.height);
  if (image_bytes > device_limit) {
    // In bytes where the rounded sizes read alike ("128 MiB, more than ... 128 MiB").
    const bool alike = format_bytes(image_bytes) == format_bytes(device_limit);
    const auto bytes = [&](uint64_t b) {
      const bool exact = alike && (b == image_bytes || b == device_limit);
      return format_bytes(b) + (exact ? " (" + std::to_string(b) + " bytes)" : "");
    };
    const uint64_t side = uint64_t(std::sqrt(double(device_limit / 16)));
    throw std::runtime_error("render settings: a " + size + " image needs a " + bytes(image_bytes) +
                             " image buffer, more than " + ctx.device_name() + " can bind (maxStorageBufferRange " +
                             bytes(ctx.limits().maxStorageBufferRange) + ", largest memory heap " +
                             bytes(largest_heap) + "); at most about " + std::to_string(side) + "x" +
                             std::to_string(side) + " pixels fit");
  }
  check_memory(pixels * 20 + pixels * 3, "render settings: reading back a " + size + " image");
}

GpuRenderer::GpuRenderer(Context& ctx, const DeviceField& field, const VolumeGeometry& geometry)
    : ctx_(ctx),
      field_(field),
      geometry_(geometry),
      kernel_(ctx, uint32_t(field.chunk_count())),
      scratch_(std::make_unique<Scratch>()) {}

GpuRenderer::~GpuRenderer() = default;

RenderedImage GpuRenderer::render(const FieldMapping& mapping, const Buffer& tf, const RenderSettings& s,
                                  Progress* progress, double* gpu_ms, RenderCallTimes* times) const {
  return render_impl(mapping, tf, s, progress, gpu_ms, times, true);
}

RenderedImage GpuRenderer::render_colours(const FieldMapping& mapping, const Buffer& tf, const RenderSettings& s,
                                          RenderCallTimes* times) const {
  return render_impl(mapping, tf, s, nullptr, nullptr, times, false);
}

namespace {
// Pictures up to this many pixels render into buffers the renderer keeps (36 MiB at the limit:
// image, stop indices, read-back staging); larger ones allocate for the call and free after.
constexpr uint64_t kKeptPixels = uint64_t(1024) * 1024;

// `kept` when it holds `bytes` (grown once when it does not), else a buffer for this call.
Buffer& scratch(Context& ctx, Buffer& kept, Buffer& once, uint64_t bytes, bool keep, MemoryUsage usage,
                const char* name) {
  Buffer& b = keep ? kept : once;
  if (!b || b.size() < bytes) {
    b = Buffer();  // the old one first: the footprint stays bounded
    b = Buffer(ctx, bytes, usage, name);
  }
  return b;
}
}  // namespace

struct GpuRenderer::Scratch {
  std::mutex mutex;  // one call at a time uses the kept buffers
  Buffer views, image, stop, staging;
};

RenderedImage GpuRenderer::render_impl(const FieldMapping& mapping, const Buffer& tf, const RenderSettings& s,
                                       Progress* progress, double* gpu_ms, RenderCallTimes* times,
                                       bool read_stop) const {
  const auto t0 = std::chrono::steady_clock::now();
  const MarchConstants march = march_constants(s, geometry_);
  const CameraFrame frame = orbit_frame(s.camera, geometry_, s.width, s.height);
  const gpu::RenderView view = make_render_view(frame);
  const gpu::RenderPush push = make_render_push(geometry_, march, mapping, field_, s.width, s.height, 1);
  const uint64_t pixels = uint64_t(s.width) * s.height;
  check_render_size(ctx_, s);
  // One submission per band, the camera written and the image (and stop indices) copied to
  // host-visible memory inside them: a picture without progress is one submission and one wait,
  // into buffers kept between calls (an allocation costs a GPU driver far more than the copy).
  std::lock_guard lock(scratch_->mutex);
  const bool keep = pixels <= kKeptPixels;
  Buffer views_once, image_once, stop_once, staging_once;
  Buffer& views = scratch(ctx_, scratch_->views, views_once, sizeof(gpu::RenderView), true, MemoryUsage::Device,
                          "render camera");
  Buffer& image = scratch(ctx_, scratch_->image, image_once, pixels * 16, keep, MemoryUsage::Device, "render image");
  Buffer& stop = scratch(ctx_, scratch_->stop, stop_once, pixels * 4, keep, MemoryUsage::Device, "render stop index");
  const uint64_t read_bytes = pixels * (read_stop ? 20 : 16);
  Buffer& staging =
      scratch(ctx_, scratch_->staging, staging_once, read_bytes, keep, MemoryUsage::Readback, "render read-back");

  // Bands keep each submission short enough to report progress; multiples of the tile height.
  const uint32_t band = progress ? std::max<uint32_t>(TFM_RENDER_TILE, (s.height / 32 + 7) / 8 * 8) : s.height;
  double total_ms = 0.0;
  bool timed = ctx_.timestamps_supported();
  for (uint32_t row = 0; row < s.height; row += band) {
    checkpoint("render");
    const uint32_t rows = std::min(band, s.height - row);
    CommandBatch batch(ctx_);
    if (row == 0) {
      batch.update(views, 0, &view, sizeof view);
      batch.barrier();  // the camera before the kernel reads it
    }
    const uint32_t t0 = batch.timestamp();
    kernel_.record(batch, field_, tf, views, push, image, stop, row, rows);
    const uint32_t t1 = batch.timestamp();
    if (row + rows == s.height) {  // the last band: the picture to host-visible memory
      batch.barrier();  // every band's writes of the image and stop indices before the copies read them
      batch.copy(image, 0, staging, 0, pixels * 16);
      if (read_stop) batch.copy(stop, 0, staging, pixels * 16, pixels * 4);
      batch.barrier_to_host();
    }
    batch.submit_and_wait();
    const double ms = batch.elapsed_ms(t0, t1);
    if (ms < 0) timed = false;
    total_ms += ms;
    if (progress) progress->update(row + rows);
  }
  if (gpu_ms) *gpu_ms = timed ? total_ms : -1.0;
  const auto t1 = std::chrono::steady_clock::now();

  RenderedImage out;
  out.width = s.width;
  out.height = s.height;
  out.rgba.resize(pixels * 4);
  const char* mapped = static_cast<const char*>(staging.mapped());
  std::memcpy(out.rgba.data(), mapped, pixels * 16);
  if (read_stop) {
    out.stop.resize(pixels);
    std::memcpy(out.stop.data(), mapped + pixels * 16, pixels * 4);
  }
  if (times) {
    const auto t2 = std::chrono::steady_clock::now();
    times->dispatch_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    times->readback_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  }
  return out;
}

RenderedImage render_volume(Context& ctx, const Volume& volume, const TransferFunction& tf, const FieldRange& range,
                            const RenderSettings& settings, Progress* progress) {
  const VolumeGeometry geometry = VolumeGeometry::from(volume.dims, volume.spacing, settings.z_scale);
  if (volume.values.size() != volume.voxel_count())
    throw std::runtime_error(volume.name + ": value count differs from the grid size");
  // Read in place on a CPU device (the copy doubled render's memory on lavapipe), else uploaded.
  const DeviceField field =
      field_over_host_values(ctx, volume.values, (volume.name.empty() ? "render field" : volume.name) + ": uploading the field");
  Buffer tf_buffer = upload_tf(ctx, tf, "render TF");
  GpuRenderer renderer(ctx, field, geometry);
  return renderer.render(make_mapping(range, uint32_t(tf.size())), tf_buffer, settings, progress);
}

void draw_markers(Image& image, const VolumeGeometry& geometry, const RenderSettings& settings,
                  const std::vector<std::array<uint64_t, 3>>& markers) {
  if (markers.empty()) return;
  const CameraFrame frame = orbit_frame(settings.camera, geometry, image.width, image.height);
  const double radius = marker_radius(image.width, image.height);
  for (const auto& m : markers) {
    const auto p = project_to_pixel(frame, geometry, glm::dvec3(double(m[0]), double(m[1]), double(m[2])), image.width,
                                    image.height);
    if (p) draw_dot(image, p->x + 0.5, p->y + 0.5, radius, {220, 20, 20}, {255, 255, 255});
  }
}

}  // namespace tfm
