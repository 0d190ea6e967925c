// Pipelines and dispatch of the gradient-descent kernels.
#include "tfmatch/kernels/gradient_descent.h"

#include "tfmatch/shaders/shader_registry.h"

#include <stdexcept>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/kernels/voxel_pair.h"

namespace tfm {

static_assert(sizeof(gpu::GdUpdatePush) == 48, "GdUpdatePush must match the GLSL std430 block");

namespace {
// Bindings in the order record() lists each kernel's buffers.
constexpr auto kUpdateBindingCounts =
    gpu::binding_counts({TFM_GD_UPDATE_BINDING_ACCUM, TFM_GD_UPDATE_BINDING_X, TFM_GD_UPDATE_BINDING_M,
                         TFM_GD_UPDATE_BINDING_V, TFM_GD_UPDATE_BINDING_INV_DIAG, TFM_GD_UPDATE_BINDING_GRADIENT});
}  // namespace

uint64_t gd_accumulator_bytes(uint32_t tf_size) { return uint64_t(TFM_GD_ACCUM_WORDS(tf_size)) * sizeof(uint32_t); }

GdGradientKernel::GdGradientKernel(Context& ctx, uint32_t tf_size, bool l1, ReductionOptions options)
    : pass_(ctx, tf_size,
            {"gd_gradient", TFM_TF_GRADIENT_SLOTS(tf_size), kPrivateMaxBins, {{TFM_GD_SPEC_LOSS_L1, l1 ? 1u : 0u}}},
            options) {}

void GdGradientKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                              const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                              const Buffer& x, Buffer& accum) const {
  const uint32_t n = pass_.tf_size();
  if (accum.size() < gd_accumulator_bytes(n) || x.size() < uint64_t(n) * 16)
    throw std::invalid_argument("gd_gradient: accumulator or TF buffer too small");
  pass_.record(batch, ref, opt, ref_map, opt_map, ref_tf, x, accum);
}

GdUpdateKernel::GdUpdateKernel(Context& ctx) {
  PipelineDesc desc;
  desc.shader = "gd_update";
  desc.binding_counts = gpu::to_vector(kUpdateBindingCounts);
  desc.push_constant_bytes = sizeof(gpu::GdUpdatePush);
  desc.workgroup_size = TFM_VECTOR_WORKGROUP;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_VECTOR_WORKGROUP}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

void GdUpdateKernel::record(CommandBatch& batch, const gpu::GdUpdatePush& push, const GdUpdateBuffers& b) const {
  if (!b.accum || !b.x || !b.m || !b.v || !b.inv_diag || !b.gradient)
    throw std::invalid_argument("gd_update: missing buffer");
  const uint64_t rgba = uint64_t(push.tf_size) * 16;
  if (b.accum->size() < gd_accumulator_bytes(push.tf_size) || b.x->size() < rgba || b.m->size() < rgba ||
      b.v->size() < rgba || b.gradient->size() < rgba || b.inv_diag->size() < uint64_t(push.tf_size) * 4)
    throw std::invalid_argument("gd_update: a buffer is smaller than N entries need");
  if (!(push.reg_scale > 0.0f)) throw std::invalid_argument("gd_update: reg_scale must be positive");
  batch.dispatch(*pipeline_, {*b.accum, *b.x, *b.m, *b.v, *b.inv_diag, *b.gradient}, push, {1});
}

}  // namespace tfm
