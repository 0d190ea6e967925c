// Pipelines and dispatches of the visibility weights (kernels/visibility_weights.h).
#include "tfmatch/kernels/visibility_weights.h"

#include <algorithm>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/shaders/shader_registry.h"
#include "tfmatch/shaders/visibility_layout.h"

namespace tfm {

static_assert(sizeof(gpu::VisibilityPush) == 88, "VisibilityPush must match the GLSL push-constant block");

namespace {
constexpr auto kVisibilityBindingCounts =
    gpu::binding_counts({TFM_VIS_BINDING_FIELD, TFM_VIS_BINDING_TF, TFM_VIS_BINDING_VIEWS, TFM_VIS_BINDING_OUT,
                         TFM_VIS_BINDING_MAX, TFM_VIS_BINDING_PARTIAL},
                        TFM_VIS_BINDING_FIELD, TFM_RENDER_MAX_CHUNKS);
constexpr uint32_t kWorkgroup = 64;
// Samples one invocation marches per dispatch at most: llvmpipe ends an invocation's loops after
// 65535 iterations in all (shaders/correlation_common.glsl), so the views come in batches, and
// rays longer than that one view at a time in parts.
constexpr uint64_t kMaxSamplesPerInvocation = 60000;
// Loop iterations besides the march: the views' loop and its entry.
constexpr uint64_t kOtherLoops = 2;

SharedPipeline make_pipeline(Context& ctx, uint32_t chunks, uint32_t mode) {
  PipelineDesc desc;
  desc.shader = "visibility_weights";
  desc.binding_counts = gpu::to_vector(kVisibilityBindingCounts);
  desc.binding_kinds = march_binding_kinds(desc.binding_counts.size(), TFM_VIS_BINDING_FIELD, TFM_VIS_BINDING_TF);
  desc.push_constant_bytes = sizeof(gpu::VisibilityPush);
  desc.workgroup_size = kWorkgroup;
  desc.specialization =
      gpu::by_id({{TFM_SPEC_WORKGROUP_X, kWorkgroup}, {TFM_RENDER_SPEC_CHUNKS, chunks}, {TFM_VIS_SPEC_MODE, mode}});
  desc.spirv = shader_spirv(desc.shader);
  return shared_pipeline(ctx, desc);
}
}  // namespace

VisibilityWeightsKernel::VisibilityWeightsKernel(Context& ctx, uint32_t field_chunks)
    : ctx_(ctx), chunks_(field_chunks) {
  if (field_chunks == 0 || field_chunks > TFM_RENDER_MAX_CHUNKS)
    throw std::invalid_argument("visibility weights: the field has " + std::to_string(field_chunks) +
                                " chunks; the kernel binds 1 to " + std::to_string(TFM_RENDER_MAX_CHUNKS));
  sum_ = make_pipeline(ctx, field_chunks, TFM_VIS_MODE_SUM);
  quantize_ = make_pipeline(ctx, field_chunks, TFM_VIS_MODE_QUANTIZE);
}

VisibilityWeightsKernel::~VisibilityWeightsKernel() = default;

VisibilityWeights VisibilityWeightsKernel::compute(const DeviceField& ref, const VolumeGeometry& geometry,
                                                   const FieldMapping& ref_map, const Buffer& ref_tf,
                                                   const RenderSettings& settings,
                                                   std::span<const OrbitCamera> cameras,
                                                   uint32_t max_part_samples) const {
  if (cameras.empty()) throw std::invalid_argument("visibility weights: no cameras");
  if (ref.chunk_count() != chunks_)
    throw std::invalid_argument("visibility weights: the field's chunk count differs from the kernel's");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16)
    throw std::invalid_argument("visibility weights: TF buffer smaller than its mapping's size");
  const MarchConstants march = march_constants(settings, geometry);
  // The renderer's push block carries the grid and marching constants, checked as for a render.
  const gpu::RenderPush rp = make_render_push(geometry, march, ref_map, ref, settings.width, settings.height, 1);
  // Views come in batches of up to kMaxSamplesPerInvocation samples; longer rays one view at a
  // time in parts, each voxel's transmittance kept between them in `partial`.
  const auto parts = march_parts(ctx_, rp.max_steps, kOtherLoops, max_part_samples);
  std::vector<gpu::RenderView> views;
  for (const OrbitCamera& c : cameras) {
    RenderSettings s = settings;
    s.camera = c;
    views.push_back(make_render_view(orbit_frame(c, geometry, s.width, s.height)));
  }
  const Buffer view_buffer = make_buffer<gpu::RenderView>(ctx_, std::span<const gpu::RenderView>(views), "visibility cameras");
  VisibilityWeights out{DeviceField(ctx_, ref.voxel_count(), "visibility weights", ref.chunk_voxels())};
  if (out.weights.chunk_voxels() != ref.chunk_voxels() || out.weights.chunk_count() != ref.chunk_count())
    throw std::invalid_argument("visibility weights: the reference field's chunking cannot be repeated on this device");
  Buffer max_word(ctx_, 4, MemoryUsage::Device, "visibility weights maximum");
  std::optional<DeviceField> partial;
  if (parts.size() > 1)
    partial.emplace(ctx_, ref.voxel_count(), "visibility weights: rays between parts", ref.chunk_voxels());

  gpu::VisibilityPush push{};
  push.dim_x = rp.dim_x;
  push.dim_y = rp.dim_y;
  push.dim_z = rp.dim_z;
  push.chunk_voxels = rp.chunk_voxels;
  push.tf_size = rp.tf_size;
  push.tf_lo = rp.tf_lo;
  push.tf_scale = rp.tf_scale;
  push.dt = rp.dt;
  push.depth_per_alpha = rp.depth_per_alpha;
  push.stop_transmittance = rp.stop_transmittance;
  push.max_steps = rp.max_steps;
  push.inv_axis_x = rp.inv_axis_x;
  push.inv_axis_y = rp.inv_axis_y;
  push.inv_axis_z = rp.inv_axis_z;
  const uint32_t batch_views = uint32_t(std::max<uint64_t>(1, kMaxSamplesPerInvocation / std::max(1u, rp.max_steps)));
  const uint64_t max_groups = ctx_.limits().maxComputeWorkGroupCount[0];
  const uint64_t range = std::min<uint64_t>(max_groups * kWorkgroup, uint64_t(1) << 30);
  const Binding field = march_field_binding(ref);
  const Binding tf = march_tf_binding(ref_tf, ref_map.tf_size);

  CommandBatch batch(ctx_);
  const uint32_t t0 = batch.timestamp();
  batch.fill(max_word, 0u);
  batch.barrier();
  // Every range of voxels of every chunk; `partial`'s chunk (or, for whole rays, which never
  // touch it, the weights' own) at its binding.
  auto each_range = [&](const ComputePipeline& pipeline) {
    for (size_t c = 0; c < out.weights.chunk_count(); ++c)
      for (uint64_t first = 0; first < out.weights.chunk_size(c); first += range) {
        push.out_first = uint32_t(out.weights.chunk_begin(c));
        push.first_voxel = uint32_t(out.weights.chunk_begin(c) + first);
        push.voxel_count = uint32_t(std::min(range, out.weights.chunk_size(c) - first));
        const Buffer& chunk = out.weights.chunk(c);
        batch.dispatch(pipeline, {field, tf, view_buffer, chunk, max_word, partial ? partial->chunk(c) : chunk}, push,
                       Groups{uint32_t((push.voxel_count + kWorkgroup - 1) / kWorkgroup)});
      }
  };
  if (parts.size() == 1) {
    for (uint32_t v = 0; v < views.size(); v += batch_views) {
      push.view_first = v;
      push.view_count = std::min<uint32_t>(batch_views, uint32_t(views.size()) - v);
      push.finish = v + push.view_count == views.size() ? 1u : 0u;
      each_range(*sum_);
      batch.barrier();  // the next batch of views adds to these sums
    }
  } else {
    push.view_count = 1;
    for (uint32_t v = 0; v < views.size(); ++v)
      for (size_t i = 0; i < parts.size(); ++i) {
        push.view_first = v;
        push.sample_first = parts[i].first;
        push.sample_end = parts[i].second;
        push.finish = v + 1 == views.size() && i + 1 == parts.size() ? 1u : 0u;
        each_range(*sum_);
        batch.barrier();  // the next part resumes these rays, the next view adds to these sums
      }
    push.sample_first = push.sample_end = 0;
  }
  each_range(*quantize_);
  const uint32_t t1 = batch.timestamp();
  batch.submit_and_wait();
  out.gpu_ms = batch.elapsed_ms(t0, t1);
  uint32_t bits = 0;
  readback(ctx_, max_word, &bits, 4);
  float max_sum = 0.0f;
  std::memcpy(&max_sum, &bits, 4);
  out.max_sum = max_sum;
  if (!(max_sum > 0.0f))
    throw std::runtime_error("visibility weights: no voxel is in the view of any of the " +
                             std::to_string(cameras.size()) + " cameras");
  return out;
}

}  // namespace tfm
