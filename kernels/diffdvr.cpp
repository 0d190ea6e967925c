// Pipelines and dispatch recording of the DiffDVR passes: the forward pass is render_image.comp in
// its DiffDVR state mode, the backward pass diffdvr_backward.comp.
#include "tfmatch/kernels/diffdvr.h"

#include "tfmatch/shaders/shader_registry.h"

#include <stdexcept>
#include <string>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

static_assert(uint32_t(ImageLoss::L2) == TFM_DIFFDVR_LOSS_L2 && uint32_t(ImageLoss::L1) == TFM_DIFFDVR_LOSS_L1,
              "the host enum is the specialization constant");

namespace {

void check_chunks(uint32_t chunks) {
  if (chunks == 0 || chunks > TFM_RENDER_MAX_CHUNKS)
    throw std::runtime_error("diffdvr: the field needs " + std::to_string(chunks) +
                             " buffers; the kernels bind at most " + std::to_string(TFM_RENDER_MAX_CHUNKS) +
                             " (volume too large for this device)");
}

// The checks both passes share: chunking, buffer sizes, row band.
void check_pass(const DeviceField& field, uint32_t chunks, const Buffer& tf, const Buffer& views,
                const gpu::RenderPush& push, const Buffer& state, const Buffer& stop, uint32_t row_begin,
                uint32_t row_count) {
  if (field.chunk_count() != chunks) throw std::invalid_argument("diffdvr: field chunk count differs from pipeline's");
  const uint64_t pixels = uint64_t(push.width) * push.height * push.view_count;
  if (state.size() < pixels * 16 || stop.size() < pixels * 4)
    throw std::invalid_argument("diffdvr: state buffers too small for the images");
  if (views.size() < uint64_t(push.view_count) * sizeof(gpu::RenderView))
    throw std::invalid_argument("diffdvr: fewer camera records than views");
  if (tf.size() < uint64_t(push.tf_size) * 16) throw std::invalid_argument("diffdvr: TF buffer smaller than tf_size");
  if (uint64_t(row_begin) + row_count > push.height) throw std::invalid_argument("diffdvr: row band outside the image");
}

// Workgroups of `columns` image columns and `rows` rows each over the band.
Groups tiles(const gpu::RenderPush& push, uint32_t row_count, uint32_t columns, uint32_t rows) {
  return {(push.width + columns - 1) / columns, (row_count + rows - 1) / rows, push.view_count};
}

// diffdvr_backward.comp's bindings in the order record() lists its buffers.
constexpr auto kBackwardBindingCounts = gpu::binding_counts(
    {TFM_DIFFDVR_BWD_BINDING_FIELD, TFM_DIFFDVR_BWD_BINDING_TF, TFM_DIFFDVR_BWD_BINDING_VIEWS,
     TFM_DIFFDVR_BWD_BINDING_STATE, TFM_DIFFDVR_BWD_BINDING_STOP, TFM_DIFFDVR_BWD_BINDING_TARGET,
     TFM_DIFFDVR_BWD_BINDING_ACCUM, TFM_DIFFDVR_BWD_BINDING_RESUME},
    TFM_DIFFDVR_BWD_BINDING_FIELD, TFM_RENDER_MAX_CHUNKS);

}  // namespace

DiffDvrForwardKernel::DiffDvrForwardKernel(Context& ctx, uint32_t field_chunks, uint32_t max_part_samples)
    : ctx_(ctx), chunks_(field_chunks), max_part_samples_(max_part_samples) {
  // The renderer's pipeline in the mode that stores (C, T): the same march as every image shown.
  pipeline_ = shared_pipeline(
      ctx, render_image_pipeline_desc(field_chunks, TFM_RENDER_MODE_DIFFDVR_STATE, "diffdvr"));
}

void DiffDvrForwardKernel::record(CommandBatch& batch, const DeviceField& field, const Buffer& tf,
                                  const Buffer& views, gpu::RenderPush push, Buffer& state, Buffer& stop,
                                  uint32_t row_begin, uint32_t row_count) const {
  check_pass(field, chunks_, tf, views, push, state, stop, row_begin, row_count);
  push.row_offset = row_begin;
  push.row_end = row_begin + row_count;
  // Buffers in the binding order of gpu::kRenderBindingCounts; the state is the renderer's image.
  // Long rays in parts where the device limits an invocation's loops, as the renderer's.
  dispatch_forward_parts(ctx_, batch, *pipeline_,
                         {march_field_binding(field), march_tf_binding(tf, push.tf_size), views, state, stop}, push,
                         tiles(push, row_count, TFM_RENDER_TILE, TFM_RENDER_TILE), max_part_samples_);
}

namespace {

bool has_subgroup_reductions(const Context& ctx) {
  const uint32_t need = VK_SUBGROUP_FEATURE_BASIC_BIT | VK_SUBGROUP_FEATURE_VOTE_BIT | VK_SUBGROUP_FEATURE_ARITHMETIC_BIT;
  return (ctx.subgroup_operations() & need) == need;
}

}  // namespace

std::string DiffDvrBackwardKernel::unsupported(const Context& ctx, uint32_t tf_size, ReductionMode mode) {
  const uint64_t shared_bytes = uint64_t(TFM_DIFFDVR_SLOTS(tf_size)) * gpu::kFixedSlotBytes;
  if (mode == ReductionMode::Private && tf_size > private_limit(ctx, kDiffDvrPrivateMaxBins))
    return "private histograms hold at most " + std::to_string(private_limit(ctx, kDiffDvrPrivateMaxBins)) +
           " TF entries on this device, not " +
           std::to_string(tf_size);
  if (mode == ReductionMode::Private && !has_subgroup_reductions(ctx))
    return "private histograms need subgroup basic, vote and arithmetic operations in compute shaders; the "
           "device lacks them";
  if (mode == ReductionMode::RunsShared && shared_bytes > ctx.limits().maxComputeSharedMemorySize)
    return std::to_string(tf_size) + " TF entries need " + std::to_string(shared_bytes) +
           " bytes of shared memory; the device has " + std::to_string(ctx.limits().maxComputeSharedMemorySize);
  return {};
}

// A private lane marches TFM_DIFFDVR_PRIVATE_PIXELS rays back and zeroes and adds its N-entry
// histogram; a runs lane one ray. Nested on llvmpipe: an inner iteration steps every lane still in
// its run (each at least one sample, so at most 8 a sample for a vector of 8 lanes), and the outer
// loop and the inner loop's entries come at most once a sample each.
uint32_t DiffDvrBackwardKernel::loops_per_sample(ReductionMode mode, RunsMarch march) {
  if (mode == ReductionMode::Private) return TFM_DIFFDVR_PRIVATE_PIXELS;
  return march == RunsMarch::Flat ? 1u : 10u;
}

uint64_t DiffDvrBackwardKernel::other_loops(ReductionMode mode, uint32_t tf_size) {
  return mode == ReductionMode::Private ? 2ull * tf_size + 8 : 8;
}

ReductionMode DiffDvrBackwardKernel::choose(const Context& ctx, uint32_t tf_size, ReductionMode mode,
                                            uint32_t max_steps) {
  if (mode != ReductionMode::Auto) return mode;
  const bool private_rays_fit =
      max_steps == 0 || march_loops_fit(ctx, max_steps, loops_per_sample(ReductionMode::Private, RunsMarch::Auto),
                                        other_loops(ReductionMode::Private, tf_size));
  if (is_cpu_device(ctx) && private_rays_fit && unsupported(ctx, tf_size, ReductionMode::Private).empty())
    return ReductionMode::Private;
  if (unsupported(ctx, tf_size, ReductionMode::RunsShared).empty()) return ReductionMode::RunsShared;
  return ReductionMode::RunsGlobal;
}

DiffDvrBackwardKernel::DiffDvrBackwardKernel(Context& ctx, uint32_t field_chunks, uint32_t tf_size, ImageLoss loss,
                                             ReductionMode mode, RunsMarch march, uint32_t max_part_samples)
    : ctx_(ctx),
      chunks_(field_chunks),
      tf_size_(tf_size),
      mode_(mode),
      march_(march),
      max_part_samples_(max_part_samples) {
  check_chunks(field_chunks);
  check_table_size(tf_size);
  mode_ = choose(ctx, tf_size, mode);
  if (march_ == RunsMarch::Auto) march_ = ctx.loop_iteration_limit() != 0 ? RunsMarch::Flat : RunsMarch::Nested;
  if (const std::string why = unsupported(ctx, tf_size, mode_); !why.empty())
    throw std::runtime_error("diffdvr backward: " + why);
  const bool use_shared = mode_ == ReductionMode::RunsShared;
  const bool use_private = mode_ == ReductionMode::Private;
  PipelineDesc desc;
  desc.shader = use_private ? "diffdvr_backward_private" : "diffdvr_backward";
  desc.binding_counts = gpu::to_vector(kBackwardBindingCounts);
  desc.binding_kinds =
      march_binding_kinds(desc.binding_counts.size(), TFM_DIFFDVR_BWD_BINDING_FIELD, TFM_DIFFDVR_BWD_BINDING_TF);
  desc.push_constant_bytes = sizeof(gpu::RenderPush);
  desc.workgroup_size = TFM_DIFFDVR_BACKWARD_TILE * TFM_DIFFDVR_BACKWARD_TILE;
  const uint32_t shared_slots = use_shared ? slots() : 1u;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_DIFFDVR_BACKWARD_TILE},
                                    {TFM_SPEC_WORKGROUP_Y, TFM_DIFFDVR_BACKWARD_TILE},
                                    {TFM_RENDER_SPEC_CHUNKS, field_chunks},
                                    {TFM_DIFFDVR_SPEC_LOSS, static_cast<uint32_t>(loss)},
                                    {TFM_DIFFDVR_SPEC_SHARED_WORDS, shared_slots * TFM_FIXED_SLOT_WORDS},
                                    {TFM_DIFFDVR_SPEC_USE_SHARED, use_shared ? 1u : 0u},
                                    {TFM_DIFFDVR_SPEC_PRIVATE_BINS, use_private ? tf_size : 2u},
                                    {TFM_DIFFDVR_SPEC_PIXELS_PER_LANE, use_private ? TFM_DIFFDVR_PRIVATE_PIXELS : 1u},
                                    {TFM_DIFFDVR_SPEC_FLAT_RUNS, march_ == RunsMarch::Flat && !use_private ? 1u : 0u}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

namespace {
// The parts in which a kernel of `mode` and `march` marches `push`'s rays back on `ctx`: one
// (whole rays) unless the runs are marched flat and do not fit one invocation's loops.
std::vector<std::pair<uint32_t, uint32_t>> backward_parts(const Context& ctx, const gpu::RenderPush& push,
                                                         ReductionMode mode, RunsMarch march, uint32_t tf_size,
                                                         uint32_t max_part_samples) {
  if (mode == ReductionMode::Private || march != RunsMarch::Flat) return {{0u, 0u}};
  return march_parts(ctx, push.max_steps, DiffDvrBackwardKernel::other_loops(mode, tf_size), max_part_samples);
}
}  // namespace

uint64_t DiffDvrBackwardKernel::resume_bytes(const gpu::RenderPush& push) const {
  if (backward_parts(ctx_, push, mode_, march_, tf_size_, max_part_samples_).size() == 1) return 0;
  return uint64_t(push.width) * push.height * push.view_count * 32;
}

void DiffDvrBackwardKernel::record(CommandBatch& batch, const DeviceField& field, const Buffer& tf,
                                   const Buffer& views, gpu::RenderPush push, const Buffer& state, const Buffer& stop,
                                   const Buffer& target, Buffer& accum, uint32_t row_begin, uint32_t row_count,
                                   Buffer* resume) const {
  check_pass(field, chunks_, tf, views, push, state, stop, row_begin, row_count);
  if (push.tf_size != tf_size_) throw std::invalid_argument("diffdvr: TF size differs from the kernel's");
  if (target.size() < state.size()) throw std::invalid_argument("diffdvr: target image smaller than the state");
  if (accum.size() < slots() * gpu::kFixedSlotBytes)
    throw std::invalid_argument("diffdvr: accumulator buffer too small");
  push.row_offset = row_begin;
  push.row_end = row_begin + row_count;
  // A private-histogram lane marches TFM_DIFFDVR_PRIVATE_PIXELS rows 16 apart.
  const uint32_t rows_per_group =
      TFM_DIFFDVR_BACKWARD_TILE * (mode_ == ReductionMode::Private ? TFM_DIFFDVR_PRIVATE_PIXELS : 1u);
  const Groups groups = tiles(push, row_count, TFM_DIFFDVR_BACKWARD_TILE, rows_per_group);
  // Buffers in the binding order of kBackwardBindingCounts; whole rays never touch the resume
  // binding, which then takes the accumulators' buffer as a stand-in.
  auto dispatch = [&](const Buffer& resume_buffer) {
    batch.dispatch(*pipeline_,
                   {march_field_binding(field), march_tf_binding(tf, push.tf_size), views, state, stop, target, accum,
                    resume_buffer},
                   push, groups);
  };
  const auto parts = backward_parts(ctx_, push, mode_, march_, tf_size_, max_part_samples_);
  if (parts.size() == 1) {
    check_march_loops(ctx_, push, loops_per_sample(mode_, march_), other_loops(mode_, tf_size_), "diffdvr");
    push.first_sample = push.sample_end = 0;
    dispatch(accum);
    return;
  }
  if (!resume || resume->size() < resume_bytes(push))
    throw std::invalid_argument("diffdvr: rays of " + std::to_string(push.max_steps) +
                                " samples are marched back in parts on this device; their resume buffer needs " +
                                std::to_string(resume_bytes(push)) + " bytes");
  // From the rays' ends back; each part reads the states the one before stored.
  for (size_t i = parts.size(); i-- > 0;) {
    if (i + 1 < parts.size()) batch.barrier();
    push.first_sample = parts[i].first;
    push.sample_end = parts[i].second;
    dispatch(*resume);
  }
}

void FixedPointTotals::add(const uint32_t* words) {
  for (size_t k = 0; k < whole_.size(); ++k) {
    // Two's complement: the conversion to int64 is exact (well defined since C++20), and the
    // arithmetic shift floors, so value = whole * 2^32 + fraction with 0 <= fraction < 2^32.
    const int64_t v = static_cast<int64_t>((uint64_t(words[2 * k + 1]) << 32) | words[2 * k]);
    whole_[k] += v >> 32;
    fraction_[k] += v & 0xFFFFFFFF;
  }
}

std::vector<double> FixedPointTotals::values() const {
  std::vector<double> out(whole_.size());
  for (size_t k = 0; k < out.size(); ++k) {
    const int64_t whole = whole_[k] + (fraction_[k] >> 32), fraction = fraction_[k] & 0xFFFFFFFF;
    out[k] = double(whole) + double(fraction) / TFM_FIXED_ONE;  // both exact; one rounding
  }
  return out;
}

}  // namespace tfm
