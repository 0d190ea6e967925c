// GPU normal-equation assembly and voxel loss over device fields.
#include "tfmatch/kernels/gpu_voxel_ops.h"

#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/voxel_loss.h"

namespace tfm {

GpuNormalEquations::GpuNormalEquations(Context& ctx, uint32_t tf_size, ReductionOptions options)
    : ctx_(ctx),
      kernel_(ctx, tf_size, options),
      accum_(ctx, uint64_t(kernel_.slots()) * 2 * sizeof(uint32_t), MemoryUsage::Device, "normal-equation accumulators") {
  reset();
}

void GpuNormalEquations::reset() {
  fill(ctx_, accum_, 0u);
  adds_ = 0;
  with_before_ = false;
}

double GpuNormalEquations::add(const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
                               const FieldMapping& opt_map, const Buffer& ref_tf, const FieldMapping* before_map,
                               const DeviceField* weights) {
  if (adds_ > 0 && with_before_ != (before_map != nullptr))
    throw std::invalid_argument("GpuNormalEquations::add: every part of one system must (or must not) carry the "
                                "before loss");
  CommandBatch batch(ctx_);
  uint32_t t0 = batch.timestamp();
  kernel_.record(batch, ref, opt, ref_map, opt_map, ref_tf, accum_, before_map, weights);
  ++adds_;
  with_before_ = before_map != nullptr;
  uint32_t t1 = batch.timestamp();
  batch.submit_and_wait();
  return batch.elapsed_ms(t0, t1);
}

std::vector<uint64_t> GpuNormalEquations::fixed_point_slots() const {
  std::vector<uint64_t> slots(kernel_.slots());
  // Low word first: the little-endian layout of a 64-bit integer.
  std::vector<uint32_t> words(slots.size() * 2);
  readback(ctx_, accum_, words.data(), words.size() * sizeof(uint32_t));
  for (size_t k = 0; k < slots.size(); ++k) slots[k] = uint64_t(words[2 * k]) | uint64_t(words[2 * k + 1]) << 32;
  return slots;
}

NormalEquations GpuNormalEquations::result() const { return decode(fixed_point_slots(), with_before_); }

NormalEquations GpuNormalEquations::decode(std::span<const uint64_t> slots, bool with_before) const {
  if (slots.size() != kernel_.slots())
    throw std::invalid_argument("GpuNormalEquations::decode: " + std::to_string(slots.size()) + " slots, the kernel has " +
                                std::to_string(kernel_.slots()));
  std::vector<uint32_t> words(slots.size() * 2);  // low word first, as the device holds them
  for (size_t k = 0; k < slots.size(); ++k) {
    words[2 * k] = uint32_t(slots[k]);
    words[2 * k + 1] = uint32_t(slots[k] >> 32);
  }
  return NormalEquations::from_slots(kernel_.tf_size(), decode_fixed_point(words), with_before);
}

double VoxelLoss::rmse() const {
  if (voxels == 0) return 0.0;
  return std::sqrt((squared[0] + squared[1] + squared[2] + squared[3]) / (4.0 * double(voxels)));
}

double VoxelLoss::mae() const {
  if (voxels == 0) return 0.0;
  return (absolute[0] + absolute[1] + absolute[2] + absolute[3]) / (4.0 * double(voxels));
}

namespace {

// One or two losses (TFM_LOSS_SLOTS slots each) measured in one pass.
std::vector<VoxelLoss> measure_voxel_losses(Context& ctx, const DeviceField& ref, const DeviceField& opt,
                                            const FieldMapping& ref_map, const FieldMapping& opt_map,
                                            const Buffer& ref_tf, const Buffer& opt_tf,
                                            const FieldMapping* before_map, double* gpu_ms,
                                            const VoxelLossKernel* prepared = nullptr) {
  const size_t losses = before_map ? 2 : 1;
  std::optional<VoxelLossKernel> made;
  const VoxelLossKernel& kernel = prepared ? *prepared : made.emplace(ctx);
  Buffer accum(ctx, losses * TFM_LOSS_SLOTS * gpu::kFixedSlotBytes, MemoryUsage::Device, "voxel loss accumulators");
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  batch.barrier();
  uint32_t t0 = batch.timestamp();
  kernel.record(batch, ref, opt, ref_map, opt_map, ref_tf, opt_tf, accum, before_map);
  uint32_t t1 = batch.timestamp();
  batch.submit_and_wait();
  if (gpu_ms) *gpu_ms = batch.elapsed_ms(t0, t1);
  std::vector<uint32_t> words(losses * TFM_LOSS_SLOTS * TFM_FIXED_SLOT_WORDS);
  readback(ctx, accum, words.data(), words.size() * sizeof(uint32_t));
  return decode_voxel_losses(words);
}

}  // namespace

std::vector<VoxelLoss> decode_voxel_losses(const std::vector<uint32_t>& words) {
  const std::vector<double> s = decode_fixed_point(words);
  std::vector<VoxelLoss> out(s.size() / TFM_LOSS_SLOTS);
  for (size_t l = 0; l < out.size(); ++l) {
    const double* slots = s.data() + l * TFM_LOSS_SLOTS;
    for (int c = 0; c < 4; ++c) out[l].squared[c] = slots[c], out[l].absolute[c] = slots[4 + c];
    out[l].voxels = static_cast<uint64_t>(std::llround(slots[8]));
  }
  return out;
}

VoxelLoss voxel_loss_gpu(Context& ctx, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
                         const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, double* gpu_ms) {
  return measure_voxel_losses(ctx, ref, opt, ref_map, opt_map, ref_tf, opt_tf, nullptr, gpu_ms)[0];
}

VoxelLosses voxel_losses_gpu(Context& ctx, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
                             const FieldMapping& before_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                             const Buffer& opt_tf, double* gpu_ms, const VoxelLossKernel* kernel) {
  const std::vector<VoxelLoss> l =
      measure_voxel_losses(ctx, ref, opt, ref_map, opt_map, ref_tf, opt_tf, &before_map, gpu_ms, kernel);
  return {l[1], l[0]};
}

VoxelLoss voxel_loss_from_system(const NormalEquations& eq, std::span<const float> rgba) {
  if (rgba.size() != size_t(eq.n) * 4)
    throw std::invalid_argument("voxel_loss_from_system: the TF has " + std::to_string(rgba.size() / 4) +
                                " entries, the system " + std::to_string(eq.n));
  Eigen::Matrix<double, Eigen::Dynamic, 4> x(eq.n, 4);
  for (uint32_t j = 0; j < eq.n; ++j)
    for (int c = 0; c < 4; ++c) x(j, c) = rgba[4 * j + c];
  VoxelLoss loss;
  loss.squared = eq.residual_squared_per_channel(x);
  loss.absolute.fill(std::numeric_limits<double>::quiet_NaN());
  loss.voxels = eq.voxels;
  return loss;
}

VoxelLoss voxel_loss_before(const NormalEquations& eq, std::span<const float> ref_rgba) {
  if (!eq.before) return voxel_loss_from_system(eq, ref_rgba);
  VoxelLoss loss;
  loss.squared = *eq.before;
  loss.absolute.fill(std::numeric_limits<double>::quiet_NaN());
  loss.voxels = eq.voxels;
  return loss;
}

Buffer upload_tf(Context& ctx, std::span<const float> rgba, const std::string& name) {
  if (rgba.size() % 4 != 0 || rgba.size() < 8)
    throw std::invalid_argument("upload_tf(" + name + "): need 4 floats per entry and at least 2 entries");
  return make_buffer<float>(ctx, rgba, name);
}

}  // namespace tfm
