// The recording of preconditioned CGLS on the device (see device_cgls.h).
#include "tfmatch/kernels/device_cgls.h"

#include <algorithm>
#include <stdexcept>

namespace tfm {

namespace {

// The factors, once they are known to have N (and N - 1) entries: checked before any buffer is made.
const CglsFactors& checked(const CglsFactors& f, uint32_t n) {
  if (f.inv_pivot.size() != n || (!f.lower.empty() && f.lower.size() + 1 != n))
    throw std::invalid_argument("DeviceCgls: the preconditioner needs N inverse pivots and N - 1 multipliers");
  return f;
}

std::vector<float> lower_or_zeros(const CglsFactors& f, uint32_t n) {
  std::vector<float> lower(n, 0.0f);  // N floats: the shader's binding, the last unused
  std::copy(f.lower.begin(), f.lower.end(), lower.begin());
  return lower;
}

}  // namespace

DeviceCgls::DeviceCgls(Context& ctx, uint32_t tf_size, const CglsFactors& factors, const CglsWeights& weights)
    : n_(tf_size),
      weights_(weights),
      bidiagonal_(!checked(factors, tf_size).lower.empty()),  // first: the buffers below trust the sizes
      inv_pivot_(make_buffer<float>(ctx, factors.inv_pivot, "CGLS inverse pivots")),
      lower_(make_buffer<float>(ctx, lower_or_zeros(factors, tf_size), "CGLS multipliers")),
      z_(ctx, uint64_t(tf_size) * 16, MemoryUsage::Device, "CGLS z"),
      s_accum_(ctx, signed_accumulator_bytes(tf_size), MemoryUsage::Device, "CGLS S^T r accumulators"),
      delta_accum_(ctx, TFM_GATHER_NORM_SLOTS * gpu::kFixedSlotBytes, MemoryUsage::Device,
                   "CGLS ||S p||^2 accumulators"),
      x_(ctx, uint64_t(tf_size) * 16, MemoryUsage::Device, "CGLS x"),
      p_(ctx, uint64_t(tf_size) * 16, MemoryUsage::Device, "CGLS p"),
      state_(ctx, sizeof(gpu::CglsState), MemoryUsage::Device, "CGLS state"),
      gather_(ctx, false, true, true),
      scatter_(ctx, tf_size, false),
      scatter_update_(ctx, tf_size, true),
      vectors_(ctx) {}

void DeviceCgls::record_stage(CommandBatch& batch, uint32_t stage) {
  vectors_.record(batch, stage, n_, weights_.ridge, weights_.smooth, weights_.tolerance, buffers());
}

CglsBuffers DeviceCgls::buffers() {
  return {&s_accum_, &delta_accum_, CglsPreconditioner{&inv_pivot_, &lower_, &z_, bidiagonal_}, &x_, &p_, &state_};
}

void DeviceCgls::record_start(CommandBatch& batch, VoxelVectors& vectors) {
  batch.fill(s_accum_, 0u);
  // Coordinates, b and the zeroed accumulators are written before the scatter reads them.
  batch.barrier();
  scatter_.record(batch, vectors, s_accum_);  // s0 = S^T b (ends with a barrier)
  record_stage(batch, TFM_CGLS_STAGE_INIT);
}

void DeviceCgls::record_iteration(CommandBatch& batch, VoxelVectors& vectors) {
  batch.fill(delta_accum_, 0u);
  // The zeroed accumulator (and p from the previous direction stage) before the gather.
  batch.barrier();
  gather_.record(batch, vectors, n_, p_, delta_accum_, &state_);  // (ends with a barrier)
  record_stage(batch, TFM_CGLS_STAGE_STEP);
  // alpha is written, and the vector stages are done with s, before s is cleared.
  batch.barrier();
  batch.fill(s_accum_, 0u);
  batch.barrier();
  scatter_update_.record_update(batch, vectors, p_, state_, s_accum_);  // (ends with a barrier)
  record_stage(batch, TFM_CGLS_STAGE_DIRECTION);
  // p, x and the state are final before the next iteration reads them.
  batch.barrier();
}

gpu::CglsState DeviceCgls::read_state(Context& ctx) const {
  gpu::CglsState st{};
  readback(ctx, state_, &st, sizeof(st));
  return st;
}

std::vector<float> DeviceCgls::read_x(Context& ctx) const {
  std::vector<float> xs(size_t(n_) * 4);
  readback(ctx, x_, xs.data(), xs.size() * sizeof(float));
  return xs;
}

}  // namespace tfm
