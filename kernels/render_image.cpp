// Pipeline and dispatch recording of the direct volume renderer.
#include "tfmatch/kernels/render_image.h"

#include "tfmatch/shaders/shader_registry.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "tfmatch/engine/context.h"

namespace tfm {

static_assert(sizeof(gpu::RenderView) == 64, "RenderView must match the GLSL std430 struct");
static_assert(sizeof(gpu::RenderPush) == 84, "RenderPush must match the GLSL push-constant block");

std::vector<DescriptorKind> march_binding_kinds(size_t bindings, uint32_t field_binding, uint32_t tf_binding) {
  return texel_binding_kinds(bindings, {field_binding, tf_binding});
}

Binding march_field_binding(const DeviceField& field) {
  return Binding::texels(field.chunk_array(TFM_RENDER_MAX_CHUNKS), voxel_texel_format(field.format()));
}

Binding march_tf_binding(const Buffer& tf, uint32_t tf_size) {
  return Binding::texels(tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(tf_size) * 16);
}

PipelineDesc render_image_pipeline_desc(uint32_t field_chunks, uint32_t mode, const char* who) {
  if (field_chunks == 0 || field_chunks > TFM_RENDER_MAX_CHUNKS)
    throw std::runtime_error(std::string(who) + ": the field needs " + std::to_string(field_chunks) +
                             " buffers; the renderer binds at most " + std::to_string(TFM_RENDER_MAX_CHUNKS) +
                             " (volume too large for this device)");
  PipelineDesc desc;
  desc.shader = "render_image";
  desc.binding_counts = gpu::to_vector(gpu::kRenderBindingCounts);
  desc.binding_kinds = march_binding_kinds(desc.binding_counts.size(), TFM_RENDER_BINDING_FIELD, TFM_RENDER_BINDING_TF);
  desc.push_constant_bytes = sizeof(gpu::RenderPush);
  desc.workgroup_size = TFM_RENDER_TILE * TFM_RENDER_TILE;
  desc.specialization = gpu::render_specialization(field_chunks, mode);
  desc.spirv = shader_spirv(desc.shader);
  return desc;
}

namespace {
// Loop iterations a marching invocation runs outside its march (camera set-up, the box's axes),
// with margin.
constexpr uint64_t kMarchLoopReserve = 256;

// v in three significant digits, rounded up when `up` (a bound that must hold as printed).
std::string three_digits(double v, bool up = false) {
  if (up && v > 0) {
    const double unit = std::pow(10.0, std::floor(std::log10(v)) - 2);
    v = std::ceil(v / unit * (1 - 1e-12)) * unit;
  }
  char text[32];
  std::snprintf(text, sizeof(text), "%.3g", v);
  return text;
}

// The loop iterations of rays of `max_steps` samples at `loops_per_sample`, and `other_loops`.
uint64_t march_loops_needed(uint32_t max_steps, uint32_t loops_per_sample, uint64_t other_loops) {
  return uint64_t(loops_per_sample) * (uint64_t(max_steps) + 1) + other_loops + kMarchLoopReserve;
}
}  // namespace

bool march_loops_fit(const Context& ctx, uint32_t max_steps, uint32_t loops_per_sample, uint64_t other_loops) {
  const uint64_t limit = ctx.loop_iteration_limit();
  return limit == 0 || march_loops_needed(max_steps, loops_per_sample, other_loops) <= limit;
}

std::vector<std::pair<uint32_t, uint32_t>> march_parts(const Context& ctx, uint32_t max_steps, uint64_t other_loops,
                                                       uint32_t max_part) {
  const uint64_t limit = ctx.loop_iteration_limit();
  // P samples cost P + 1 iterations (the loop's entry) beside the others and the reserve.
  uint64_t per_part = max_steps;
  if (limit != 0)
    per_part = limit > other_loops + kMarchLoopReserve + 1 ? limit - other_loops - kMarchLoopReserve - 1 : 0;
  if (max_part > 0) per_part = std::min<uint64_t>(per_part, max_part);
  if (max_steps <= per_part) return {{0u, 0u}};
  if (per_part == 0) throw std::logic_error("march_parts: the device's loop limit leaves no samples");
  std::vector<std::pair<uint32_t, uint32_t>> parts;
  for (uint64_t first = 0; first < max_steps; first += per_part)
    parts.emplace_back(uint32_t(first), uint32_t(std::min<uint64_t>(first + per_part, max_steps)));
  return parts;
}

void check_march_loops(const Context& ctx, const gpu::RenderPush& push, uint32_t loops_per_sample,
                       uint64_t other_loops, const char* who) {
  if (march_loops_fit(ctx, push.max_steps, loops_per_sample, other_loops)) return;
  const uint64_t limit = ctx.loop_iteration_limit();
  const uint64_t need = march_loops_needed(push.max_steps, loops_per_sample, other_loops);
  // max_steps is ceil(box diagonal / dt) + 2: the most samples that fit, and the step they need.
  const uint64_t fits =
      limit > other_loops + kMarchLoopReserve ? (limit - other_loops - kMarchLoopReserve) / loops_per_sample : 0;
  const double diagonal_steps = double(push.max_steps) - 2.0;
  const std::string advice =
      fits > 4 ? "use a step of at least " + three_digits(double(push.dt) * diagonal_steps / double(fits - 3), true) +
                     " voxels for this volume, or another Vulkan device"
               : "this needs another Vulkan device";
  throw std::runtime_error(std::string(who) + ": rays of up to " + std::to_string(push.max_steps) +
                           " samples (the box diagonal at a step of " + three_digits(push.dt) + " voxels)" +
                           (loops_per_sample > 1
                                ? ", " + std::to_string(loops_per_sample) + " loop iterations a sample in one shader invocation,"
                                : "") +
                           " need " + std::to_string(need) + " loop iterations, more than this device's driver runs " +
                           "in one invocation (llvmpipe: " + std::to_string(limit) + ") before it ends the loops; " +
                           advice);
}

RenderImageKernel::RenderImageKernel(Context& ctx, uint32_t field_chunks, uint32_t mode, uint32_t max_part_samples)
    : ctx_(ctx),
      chunks_(field_chunks),
      rays_per_pixel_(mode == TFM_RENDER_MODE_INVERSE_CHECK ? 2u : 1u),
      max_part_samples_(max_part_samples) {
  pipeline_ = shared_pipeline(ctx, render_image_pipeline_desc(field_chunks, mode, "render"));
}

RenderImageKernel::RenderImageKernel(Context& ctx, ImageField) : ctx_(ctx), chunks_(1), image_field_(true) {
  PipelineDesc desc;
  desc.shader = "render_image_image";
  desc.binding_counts = gpu::to_vector(gpu::kRenderBindingCounts);
  desc.binding_counts.at(TFM_RENDER_BINDING_FIELD) = 1;
  desc.binding_kinds = march_binding_kinds(desc.binding_counts.size(), TFM_RENDER_BINDING_FIELD, TFM_RENDER_BINDING_TF);
  bind_fields_as_images(desc, {TFM_RENDER_BINDING_FIELD});
  desc.push_constant_bytes = sizeof(gpu::RenderPush);
  desc.workgroup_size = TFM_RENDER_TILE * TFM_RENDER_TILE;
  desc.specialization = gpu::render_specialization(1, TFM_RENDER_MODE_FORWARD);
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

void RenderImageKernel::check_field(const DeviceField& field, const gpu::RenderPush&) const {
  if (image_field_) throw std::invalid_argument("render: this pipeline reads a 3D image, not a field's buffers");
  if (field.chunk_count() != chunks_)
    throw std::invalid_argument("render: the field has " + std::to_string(field.chunk_count()) +
                                " chunks, the pipeline was made for " + std::to_string(chunks_));
}

void RenderImageKernel::check_field(const ImageFieldView& field, const gpu::RenderPush& push) const {
  if (!image_field_) throw std::invalid_argument("render: this pipeline reads a field's buffers, not a 3D image");
  check_image_field(field, "render");
  if (field.extent.width != push.dim_x || field.extent.height != push.dim_y || field.extent.depth != push.dim_z)
    throw std::invalid_argument("render: the image's extent differs from the grid");
}

void RenderImageKernel::record(CommandBatch& batch, const DeviceField& field, const Buffer& tf, const Buffer& views,
                               gpu::RenderPush push, Buffer& image, Buffer& stop, uint32_t row_begin,
                               uint32_t row_count) const {
  check_field(field, push);
  record_with(batch, march_field_binding(field), tf, views, push, image, stop, row_begin, row_count);
}

void RenderImageKernel::record(CommandBatch& batch, const ImageFieldView& field, const Buffer& tf, const Buffer& views,
                               gpu::RenderPush push, Buffer& image, Buffer& stop, uint32_t row_begin,
                               uint32_t row_count) const {
  check_field(field, push);
  record_with(batch, Binding::image(field.view, field.layout), tf, views, push, image, stop, row_begin, row_count);
}

void RenderImageKernel::record_with(CommandBatch& batch, const Binding& field, const Buffer& tf, const Buffer& views,
                                    gpu::RenderPush push, Buffer& image, Buffer& stop, uint32_t row_begin,
                                    uint32_t row_count) const {
  const uint64_t pixels = uint64_t(push.width) * push.height * push.view_count;
  if (image.size() < pixels * 16 || stop.size() < pixels * 4)
    throw std::invalid_argument("render: output buffers too small for the image");
  if (views.size() < uint64_t(push.view_count) * sizeof(gpu::RenderView))
    throw std::invalid_argument("render: fewer camera records than views");
  if (tf.size() < uint64_t(push.tf_size) * 16) throw std::invalid_argument("render: TF buffer smaller than tf_size");
  if (uint64_t(row_begin) + row_count > push.height) throw std::invalid_argument("render: row band outside the image");
  push.row_offset = row_begin;
  push.row_end = row_begin + row_count;
  const Groups groups{(push.width + TFM_RENDER_TILE - 1) / TFM_RENDER_TILE,
                      (row_count + TFM_RENDER_TILE - 1) / TFM_RENDER_TILE, push.view_count};
  // Buffers in the binding order of gpu::kRenderBindingCounts.
  const std::vector<Binding> bindings = {field, march_tf_binding(tf, push.tf_size), views, image, stop};
  // Where the driver limits an invocation's loops (llvmpipe), rays longer than it allows are
  // marched in several dispatches, each resuming from the state the one before stored in the
  // image and stop buffers (render_image.comp). The inverse check walks each ray back in the
  // invocation that marched it, so it needs whole rays.
  if (rays_per_pixel_ > 1) {
    check_march_loops(ctx_, push, rays_per_pixel_, 0, "render");
    push.first_sample = 0;
    push.sample_end = 0;
    batch.dispatch(*pipeline_, bindings, push, groups);
    return;
  }
  dispatch_forward_parts(ctx_, batch, *pipeline_, bindings, push, groups, max_part_samples_);
}

void dispatch_forward_parts(const Context& ctx, CommandBatch& batch, const ComputePipeline& pipeline,
                            const std::vector<Binding>& bindings, gpu::RenderPush push, const Groups& groups,
                            uint32_t max_part) {
  bool first = true;
  for (const auto& [begin, end] : march_parts(ctx, push.max_steps, 0, max_part)) {
    // The part before has stored every ray's state before this one reads it.
    if (!first) batch.barrier();
    first = false;
    push.first_sample = begin;
    push.sample_end = end;
    batch.dispatch(pipeline, bindings, push, groups);
  }
}

gpu::RenderView make_render_view(const CameraFrame& f) {
  gpu::RenderView v{};
  auto put = [](float* dst, const glm::dvec3& src, double w) {
    dst[0] = float(src.x), dst[1] = float(src.y), dst[2] = float(src.z), dst[3] = float(w);
  };
  put(v.eye, f.eye, f.tan_half_fov);
  put(v.forward, f.forward, f.aspect);
  put(v.right, f.right, 0.0);
  put(v.up, f.up, 0.0);
  return v;
}

// The push block for a field of `field_voxels` voxels in chunks of `chunk_voxels`.
static gpu::RenderPush render_push(const VolumeGeometry& g, const MarchConstants& m, const FieldMapping& map,
                                   uint64_t field_voxels, uint64_t chunk_voxels, uint32_t width, uint32_t height,
                                   uint32_t view_count) {
  const uint64_t voxels = g.dims[0] * g.dims[1] * g.dims[2];
  if (voxels >= (uint64_t(1) << 32))
    throw std::runtime_error("render: grids of 2^32 voxels or more are not supported (32-bit voxel indices)");
  if (field_voxels != voxels) throw std::invalid_argument("render: field size differs from the grid");
  gpu::RenderPush p{};
  p.width = width;
  p.height = height;
  p.row_end = height;  // the kernels' record() set the band they dispatch
  p.view_count = view_count;
  p.dim_x = uint32_t(g.dims[0]);
  p.dim_y = uint32_t(g.dims[1]);
  p.dim_z = uint32_t(g.dims[2]);
  p.chunk_voxels = uint32_t(chunk_voxels);
  p.tf_size = map.tf_size;
  p.tf_lo = map.lo;
  p.tf_scale = map.scale;
  p.dt = float(m.dt);
  p.depth_per_alpha = float(m.depth_per_alpha);
  p.stop_transmittance = float(m.stop_transmittance);
  p.max_steps = m.max_steps;
  p.inv_axis_x = float(1.0 / g.axis_scale.x);
  p.inv_axis_y = float(1.0 / g.axis_scale.y);
  p.inv_axis_z = float(1.0 / g.axis_scale.z);
  return p;
}

gpu::RenderPush make_render_push(const VolumeGeometry& g, const MarchConstants& m, const FieldMapping& map,
                                 const DeviceField& field, uint32_t width, uint32_t height, uint32_t view_count) {
  return render_push(g, m, map, field.voxel_count(), field.chunk_voxels(), width, height, view_count);
}

gpu::RenderPush make_render_push(const VolumeGeometry& g, const MarchConstants& m, const FieldMapping& map,
                                 const ImageFieldView& field, uint32_t width, uint32_t height, uint32_t view_count) {
  if (field.extent.width != g.dims[0] || field.extent.height != g.dims[1] || field.extent.depth != g.dims[2])
    throw std::invalid_argument("render: the image's extent differs from the grid");
  const uint64_t voxels = g.dims[0] * g.dims[1] * g.dims[2];
  return render_push(g, m, map, voxels, voxels, width, height, view_count);
}

}  // namespace tfm
