// DiffDvrGradient: the forward and backward passes of one iteration, recorded in one submission.
#include "tfmatch/solvers/solver_diffdvr.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/progress.h"

namespace tfm {
namespace {

// Bound on |contribution of one ray| to any accumulator slot: the loss is <= 4 per pixel, the
// colour gradient <= 2 per channel (|dL/dX| <= 2 times sum_k T_k (1 - tau_k) <= 1), and the
// opacity gradient <= 12 D K (|gT - gC.c| <= 12, sum_k D' tau_k T_k <= D' K for K steps of
// depth D' at opacity 1; a ray's steps share its chord, so D' K = D chord / dt <= D max_steps).
// A sum of fewer than 2^30 / bound rays stays below 2^30, half the range of the signed 32.32
// accumulators.
double ray_bound(const MarchConstants& m) { return 4.0 + 12.0 * m.depth_per_alpha * double(m.max_steps); }
constexpr double kAccumulatorBudget = double(1u << 30);

bool same_cameras(std::span<const OrbitCamera> a, const std::vector<OrbitCamera>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].azimuth_deg != b[i].azimuth_deg || a[i].elevation_deg != b[i].elevation_deg ||
        a[i].distance != b[i].distance || a[i].fov_deg != b[i].fov_deg)
      return false;
  return true;
}

}  // namespace

struct DiffDvrGradient::Buffers {
  Buffer tf, ref_state, ref_stop, opt_state, opt_stop, accum;
  Buffer resume;                // rays marched back in parts (DiffDvrBackwardKernel::resume_bytes)
  Buffer upload;                // host-visible: TF entries, then camera records
  Buffer readback;              // host-visible: the accumulators of every band
  std::vector<Buffer> views;    // camera records of each group
};

DiffDvrGradient::DiffDvrGradient(Context& ctx, const DeviceField& ref, const DeviceField& opt,
                                 const VolumeGeometry& geometry, const FieldMapping& ref_map, const Buffer& ref_tf,
                                 const FieldMapping& opt_map, const RenderSettings& settings, ImageLoss loss,
                                 ReductionMode reduction, uint32_t max_group_views)
    : ctx_(ctx),
      ref_(ref),
      opt_(opt),
      geometry_(geometry),
      ref_map_(ref_map),
      opt_map_(opt_map),
      ref_tf_(ref_tf),
      settings_(settings),
      march_(march_constants(settings, geometry)),
      forward_ref_(ctx, uint32_t(ref.chunk_count())),
      forward_opt_(ctx, uint32_t(opt.chunk_count())),
      backward_(ctx, uint32_t(opt.chunk_count()), opt_map.tf_size, loss,
                DiffDvrBackwardKernel::choose(ctx, opt_map.tf_size, reduction, march_.max_steps)),
      buffers_(std::make_unique<Buffers>()) {
  const uint64_t pixels = uint64_t(settings.width) * settings.height;
  // The largest buffer of a group: its images (16 bytes a pixel), or the states of rays marched
  // back in parts (32).
  const uint64_t one_view_resume =
      backward_.resume_bytes(make_render_push(geometry, march_, opt_map, opt, settings.width, settings.height, 1));
  const uint64_t by_memory = ctx.max_buffer_bytes() / (pixels * (one_view_resume > 0 ? 32 : 16));
  const uint64_t by_range = uint64_t(kAccumulatorBudget / (double(pixels) * ray_bound(march_)));
  if (by_memory == 0) throw std::runtime_error("diffdvr: one image of this size exceeds the device's buffer limit");
  group_ = uint32_t(std::clamp<uint64_t>(std::min(by_memory, by_range), 1, std::max(max_group_views, 1u)));
  Buffers& b = *buffers_;
  b.tf = Buffer(ctx, uint64_t(opt_map.tf_size) * 16, MemoryUsage::Device, "diffdvr: TF");
  b.accum = Buffer(ctx, uint64_t(backward_.slots()) * 8, MemoryUsage::Device, "diffdvr: accumulators");
}

DiffDvrGradient::~DiffDvrGradient() = default;

ImageLossGradient DiffDvrGradient::evaluate(const TransferFunction& tf, std::span<const OrbitCamera> cameras) {
  return evaluate_views(tf, cameras, {});
}

void DiffDvrGradient::set_view_pool(std::span<const OrbitCamera> cameras) {
  pool_cameras_.clear();
  pool_images_.clear();
  const uint32_t width = settings_.width, height = settings_.height;
  const uint64_t image_bytes = uint64_t(width) * height * 16, view_bytes = sizeof(gpu::RenderView);
  // The reference pass of evaluate(), a few cameras per submission, each image then copied into
  // a buffer of its own.
  const uint32_t batch_views = std::min<uint32_t>(group_, 8);
  // The pool's images and the pass that renders them, checked before any is made (32 views of
  // 2048 x 2048 are 2 GiB).
  check_device_memory(ctx_, cameras.size() * image_bytes + uint64_t(batch_views) * image_bytes * 5 / 4,
                      "diffdvr: the reference images of a pool of " + std::to_string(cameras.size()) + " views of " +
                          std::to_string(width) + "x" + std::to_string(height));
  Buffer views(ctx_, batch_views * view_bytes, MemoryUsage::Device, "diffdvr: pool cameras");
  Buffer state(ctx_, batch_views * image_bytes, MemoryUsage::Device, "diffdvr: pool rendering");
  Buffer stop(ctx_, batch_views * image_bytes / 4, MemoryUsage::Device, "diffdvr: pool k_stop");
  // Hundreds of views take a while on a CPU device: shown, and a Ctrl-C (or the viewer's stop)
  // ends it between submissions rather than after the whole pool.
  Progress progress("diffdvr: reference views", cameras.size());
  for (size_t first = 0; first < cameras.size(); first += batch_views) {
    try {
      checkpoint("solve");
    } catch (...) {
      pool_images_.clear();  // no pool rather than part of one
      throw;
    }
    progress.update(first);
    const uint32_t count = uint32_t(std::min<size_t>(batch_views, cameras.size() - first));
    std::vector<gpu::RenderView> records;
    for (uint32_t v = 0; v < count; ++v)
      records.push_back(make_render_view(orbit_frame(cameras[first + v], geometry_, width, height)));
    upload(ctx_, views, records.data(), records.size() * view_bytes);
    CommandBatch batch(ctx_);
    forward_ref_.record(batch, ref_, ref_tf_, views,
                        make_render_push(geometry_, march_, ref_map_, ref_, width, height, count), state, stop, 0, height);
    // The renderings are complete before they are copied out.
    batch.barrier();
    for (uint32_t v = 0; v < count; ++v) {
      pool_images_.emplace_back(ctx_, image_bytes, MemoryUsage::Device, "diffdvr: pooled reference image");
      batch.copy(state, v * image_bytes, pool_images_.back(), 0, image_bytes);
    }
    batch.submit_and_wait();
  }
  progress.finish();
  pool_cameras_.assign(cameras.begin(), cameras.end());
}

ImageLossGradient DiffDvrGradient::evaluate_pooled(const TransferFunction& tf, std::span<const uint32_t> indices) {
  if (indices.empty()) throw std::invalid_argument("diffdvr: no pooled cameras chosen");
  std::vector<OrbitCamera> cameras;
  for (uint32_t i : indices) {
    if (i >= pool_cameras_.size())
      throw std::invalid_argument("diffdvr: pool index " + std::to_string(i) + " past the pool of " +
                                  std::to_string(pool_cameras_.size()));
    cameras.push_back(pool_cameras_[i]);
  }
  return evaluate_views(tf, cameras, indices);
}

ImageLossGradient DiffDvrGradient::evaluate_views(const TransferFunction& tf, std::span<const OrbitCamera> cameras,
                                                  std::span<const uint32_t> pooled) {
  if (tf.size() != opt_map_.tf_size) throw std::invalid_argument("diffdvr: TF size differs from the mapping's");
  if (cameras.empty()) throw std::invalid_argument("diffdvr: no cameras");
  Buffers& b = *buffers_;
  const uint32_t width = settings_.width, height = settings_.height;
  const uint32_t views = uint32_t(cameras.size());
  const uint32_t group = std::min(group_, views), groups = (views + group - 1) / group;
  // Per-pixel state for one group of views: 2 x (16 + 4) bytes per ray, whatever the steps (and
  // 32 more where rays are marched back in parts).
  const uint64_t pixels = uint64_t(width) * height * group;
  const uint64_t resume_bytes =
      backward_.resume_bytes(make_render_push(geometry_, march_, opt_map_, opt_, width, height, group));
  // What grows below, checked first (its size is the image size times the views in a group: 425
  // MiB held at a budget of 150 MiB).
  const uint64_t grows = (b.opt_state.size() < pixels * 16 ? pixels * 40 : 0) + (b.resume.size() < resume_bytes ? resume_bytes : 0);
  if (grows)
    check_device_memory(ctx_, grows, "diffdvr: the ray states of " + std::to_string(group) +
                                         (group == 1 ? " view of " : " views of ") + std::to_string(width) + "x" +
                                         std::to_string(height));
  if (b.opt_state.size() < pixels * 16) {
    b.ref_state = Buffer(ctx_, pixels * 16, MemoryUsage::Device, "diffdvr: reference images");
    b.ref_stop = Buffer(ctx_, pixels * 4, MemoryUsage::Device, "diffdvr: reference k_stop");
    b.opt_state = Buffer(ctx_, pixels * 16, MemoryUsage::Device, "diffdvr: field images");
    b.opt_stop = Buffer(ctx_, pixels * 4, MemoryUsage::Device, "diffdvr: field k_stop");
    b.views.clear();
    cached_cameras_.clear();
  }
  // Allocated before recording: a buffer replaced while commands use it would be gone.
  if (b.resume.size() < resume_bytes)
    b.resume = Buffer(ctx_, resume_bytes, MemoryUsage::Device, "diffdvr: ray states between parts");
  // Backward passes in row bands whose fixed-point sums stay in range (whole images in practice).
  const double band_rays = kAccumulatorBudget / ray_bound(march_) / (double(width) * group);
  const uint32_t band_rows = std::clamp<uint32_t>(
      uint32_t(std::min(band_rays, double(height))) / TFM_DIFFDVR_BACKWARD_TILE * TFM_DIFFDVR_BACKWARD_TILE,
      std::min<uint32_t>(TFM_DIFFDVR_BACKWARD_TILE, height), height);
  const uint32_t bands_per_group = (height + band_rows - 1) / band_rows;
  const uint32_t slots = backward_.slots();
  const bool reuse_reference = pooled.empty() && groups == 1 && same_cameras(cameras, cached_cameras_);
  const uint64_t image_bytes = uint64_t(width) * height * 16;

  // Uploads through one host-visible buffer: TF entries, then the camera records.
  const uint64_t tf_bytes = uint64_t(tf.size()) * 16, view_bytes = sizeof(gpu::RenderView);
  const uint64_t upload_bytes = tf_bytes + uint64_t(views) * view_bytes;
  if (b.upload.size() < upload_bytes) b.upload = Buffer(ctx_, upload_bytes, MemoryUsage::Upload, "diffdvr: upload");
  const uint64_t readback_bytes = uint64_t(groups) * bands_per_group * slots * 8;
  if (b.readback.size() < readback_bytes)
    b.readback = Buffer(ctx_, readback_bytes, MemoryUsage::Readback, "diffdvr: accumulator readback");
  while (b.views.size() < groups)
    b.views.emplace_back(ctx_, uint64_t(group) * view_bytes, MemoryUsage::Device, "diffdvr: cameras");
  const std::vector<float> entries = tf.as_floats();
  std::memcpy(b.upload.mapped(), entries.data(), tf_bytes);
  for (uint32_t v = 0; v < views; ++v) {
    const gpu::RenderView record = make_render_view(orbit_frame(cameras[v], geometry_, width, height));
    std::memcpy(static_cast<char*>(b.upload.mapped()) + tf_bytes + v * view_bytes, &record, view_bytes);
  }

  CommandBatch batch(ctx_);
  batch.copy(b.upload, 0, b.tf, 0, tf_bytes);
  for (uint32_t g = 0; g < groups; ++g) {
    const uint32_t count = std::min(group, views - g * group);
    batch.copy(b.upload, tf_bytes + uint64_t(g) * group * view_bytes, b.views[g], 0, count * view_bytes);
  }
  batch.fill(b.accum, 0);
  // The uploads and the zeroed accumulators land before any pass reads them.
  batch.barrier();
  std::vector<uint32_t> stamps;
  uint32_t band_index = 0;
  for (uint32_t g = 0; g < groups; ++g) {
    const uint32_t count = std::min(group, views - g * group);
    const gpu::RenderPush ref_push = make_render_push(geometry_, march_, ref_map_, ref_, width, height, count);
    const gpu::RenderPush opt_push = make_render_push(geometry_, march_, opt_map_, opt_, width, height, count);
    stamps.push_back(batch.timestamp());
    if (!pooled.empty()) {
      // The kept reference images of this group's cameras become its targets.
      for (uint32_t v = 0; v < count; ++v)
        batch.copy(pool_images_[pooled[g * group + v]], 0, b.ref_state, uint64_t(v) * image_bytes, image_bytes);
    } else if (!reuse_reference) {
      forward_ref_.record(batch, ref_, ref_tf_, b.views[g], ref_push, b.ref_state, b.ref_stop, 0, height);
    }
    forward_opt_.record(batch, opt_, b.tf, b.views[g], opt_push, b.opt_state, b.opt_stop, 0, height);
    // Both images are complete before the backward pass reads them.
    batch.barrier();
    stamps.push_back(batch.timestamp());
    for (uint32_t row = 0; row < height; row += band_rows, ++band_index) {
      backward_.record(batch, opt_, b.tf, b.views[g], opt_push, b.opt_state, b.opt_stop, b.ref_state, b.accum, row,
                       std::min(band_rows, height - row), &b.resume);
      // The band's sums are complete before they are copied out ...
      batch.barrier();
      batch.copy(b.accum, 0, b.readback, uint64_t(band_index) * slots * 8, uint64_t(slots) * 8);
      // ... and copied before they are cleared; the clear also orders this group's reads of the
      // images before the next group's forward passes overwrite them.
      batch.barrier();
      batch.fill(b.accum, 0);
      batch.barrier();
    }
    stamps.push_back(batch.timestamp());
  }
  batch.submit_and_wait();
  passes_ = band_index;
  cached_cameras_.assign(cameras.begin(), cameras.end());
  if (groups != 1 || !pooled.empty()) cached_cameras_.clear();

  // Exact integer totals over the bands: the result does not depend on the grouping either.
  FixedPointTotals totals(slots);
  for (uint32_t k = 0; k < band_index; ++k)
    totals.add(static_cast<const uint32_t*>(b.readback.mapped()) + size_t(k) * slots * 2);
  const std::vector<double> sums = totals.values();
  ImageLossGradient out;
  out.gradient.assign(sums.begin(), sums.end() - 1);
  out.loss = sums.back();
  out.components = uint64_t(width) * height * views * 4;
  double fwd = 0, bwd = 0;
  bool timed = true;
  for (size_t i = 0; i + 2 < stamps.size() && timed; i += 3) {
    const double f = batch.elapsed_ms(stamps[i], stamps[i + 1]), w = batch.elapsed_ms(stamps[i + 1], stamps[i + 2]);
    if (f < 0 || w < 0) timed = false;
    fwd += f;
    bwd += w;
  }
  out.forward_gpu_ms = timed ? fwd : -1.0;
  out.backward_gpu_ms = timed ? bwd : -1.0;
  return out;
}

}  // namespace tfm
