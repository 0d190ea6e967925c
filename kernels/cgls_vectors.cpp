// Pipeline and dispatch of the CGLS vector stages.
#include "tfmatch/kernels/cgls_vectors.h"

#include "tfmatch/shaders/shader_registry.h"

#include <stdexcept>

#include "tfmatch/kernels/sparse_ops.h"

namespace tfm {

static_assert(sizeof(gpu::CglsPush) == 32, "CglsPush must match the GLSL std430 block");

namespace {
// Bindings in the order record() lists its buffers.
constexpr auto kCglsBindingCounts =
    gpu::binding_counts({TFM_CGLS_BINDING_S_ACCUM, TFM_CGLS_BINDING_DELTA_ACCUM, TFM_CGLS_BINDING_INV_PIVOT,
                         TFM_CGLS_BINDING_X, TFM_CGLS_BINDING_P, TFM_CGLS_BINDING_STATE, TFM_CGLS_BINDING_LOWER,
                         TFM_CGLS_BINDING_Z});
}  // namespace

CglsVectorsKernel::CglsVectorsKernel(Context& ctx) {
  PipelineDesc desc;
  desc.shader = "cgls_vectors";
  desc.binding_counts = gpu::to_vector(kCglsBindingCounts);
  desc.push_constant_bytes = sizeof(gpu::CglsPush);
  desc.workgroup_size = TFM_VECTOR_WORKGROUP;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_VECTOR_WORKGROUP}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

void CglsVectorsKernel::record(CommandBatch& batch, uint32_t stage, uint32_t tf_size, float ridge, float smooth,
                               float tolerance, const CglsBuffers& b) const {
  const CglsPreconditioner& pc = b.preconditioner;
  if (!b.s_accum || !b.delta_accum || !pc.inv_pivot || !pc.lower || !pc.z || !b.x || !b.p || !b.state)
    throw std::invalid_argument("cgls_vectors: missing buffer");
  const uint64_t rgba = uint64_t(tf_size) * 16;
  if (b.s_accum->size() < signed_accumulator_bytes(tf_size) ||
      b.delta_accum->size() < TFM_GATHER_NORM_SLOTS * gpu::kFixedSlotBytes ||
      pc.inv_pivot->size() < uint64_t(tf_size) * 4 || pc.lower->size() < uint64_t(tf_size) * 4 ||
      pc.z->size() < rgba || b.x->size() < rgba || b.p->size() < rgba || b.state->size() < sizeof(gpu::CglsState))
    throw std::invalid_argument("cgls_vectors: a buffer is smaller than N entries need");
  gpu::CglsPush push{};
  push.tf_size = tf_size;
  push.stage = stage;
  push.ridge_weight = ridge;
  push.smooth_weight = smooth;
  push.tolerance2 = tolerance * tolerance;
  push.bidiagonal = pc.bidiagonal ? 1u : 0u;
  batch.dispatch(*pipeline_, {*b.s_accum, *b.delta_accum, *pc.inv_pivot, *b.x, *b.p, *b.state, *pc.lower, *pc.z},
                 push, {1});
}

}  // namespace tfm
