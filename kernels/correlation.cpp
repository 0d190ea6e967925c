// Correlation fields on the device: measure names and parameter checks, the strategy per member
// count, and CorrelationKernel, which streams the ensemble through the kernels in chunks of voxels.
#include "tfmatch/kernels/correlation.h"

#include "tfmatch/shaders/shader_registry.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <tuple>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/model/correlation_reference.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/shaders/correlation_layout.h"

namespace tfm {

static_assert(sizeof(gpu::CorrelationPush) == 40, "CorrelationPush must match the GLSL std430 block");
static_assert(kMaxCorrelationBins == TFM_CORR_MAX_BINS && kMaxCorrelationK == TFM_CORR_MAX_K);
// The reference values are one texel view (TFM_CORR_BINDING_REF_VALUES) on every device: Vulkan
// guarantees maxTexelBufferElements >= 65536.
static_assert(kMaxCorrelationMembers <= 65536);

namespace {

struct MeasureInfo {
  CorrelationMeasure measure;
  const char* shader;
  uint32_t regions;  // shared-memory regions per voxel (correlation_common.glsl)
};
constexpr MeasureInfo kMeasures[] = {
    {CorrelationMeasure::Pearson, "correlation_pearson", 0},
    {CorrelationMeasure::Spearman, "correlation_spearman", 2},
    {CorrelationMeasure::Kendall, "correlation_kendall", 2},
    {CorrelationMeasure::MiBinned, "correlation_mi_binned", 1},
    {CorrelationMeasure::MiKraskov, "correlation_mi_kraskov", 3},
    {CorrelationMeasure::MiCoefficient, "correlation_mi_kraskov", 3},
};

const MeasureInfo& info(CorrelationMeasure m) {
  for (const MeasureInfo& i : kMeasures)
    if (i.measure == m) return i;
  throw std::invalid_argument("unknown correlation measure");
}

// Whether spearman and kendall compare every pair of members instead of merge-sorting them
// (shaders/correlation_layout.h).
bool pairs_compared(CorrelationMeasure measure, uint32_t members) {
  return (measure == CorrelationMeasure::Spearman && members <= TFM_CORR_SPEARMAN_PAIRS_MAX_MEMBERS) ||
         (measure == CorrelationMeasure::Kendall && members <= TFM_CORR_KENDALL_PAIRS_MAX_MEMBERS);
}

// How one measure runs for one member count (why: shaders/correlation_common.glsl).
struct Plan {
  const char* shader = nullptr;
  bool group_per_voxel = false;
  bool coefficient = false;
  uint32_t workgroup = TFM_CORR_INVOCATION_WORKGROUP;
  uint32_t region_floats = 1;
  uint32_t shared_floats = 1;
  uint64_t shared_bytes = 0;  // everything the kernel declares in workgroup-shared memory
  // The Kraskov measures: loop iterations one invocation's neighbour searches may take at worst
  // (each invocation's points, each walking past up to M - 1 others, each step costing its loop
  // and up to k + 1 of the k nearest distances' insertion loop, and two binary searches a point).
  uint64_t search_loops = 0;
};

// Loop iterations of one point's Kraskov search at worst, M members, k neighbours.
uint64_t kraskov_point_loops(uint32_t members, uint32_t k) {
  return uint64_t(members - 1) * (k + 2) + 4 * (std::bit_width(members) + 1) + 4;
}

// Loop iterations an invocation's Kraskov searches may take: 3/4 of llvmpipe's 65535, the rest
// for the sort and the voxel's other loops (a few thousand at most).
constexpr uint64_t kKraskovSearchBudget = 49152;

// `max_workgroup`: the largest workgroup the plan may ask for (CorrelationKernel::max_workgroup).
Plan make_plan(const CorrelationParams& params, uint32_t members, uint32_t max_workgroup) {
  const CorrelationMeasure measure = params.measure;
  const MeasureInfo& mi = info(measure);
  Plan p;
  p.shader = mi.shader;
  p.coefficient = measure == CorrelationMeasure::MiCoefficient;
  // Pearson streams over the members whatever their number; binned MI counts per x bin up to
  // its own limit (shaders/correlation_layout.h).
  const uint32_t invocation_max = measure == CorrelationMeasure::Pearson    ? kMaxCorrelationMembers
                                  : measure == CorrelationMeasure::MiBinned ? TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS
                                                                            : TFM_CORR_INVOCATION_MAX_MEMBERS;
  p.group_per_voxel = members > invocation_max;
  uint32_t regions = mi.regions;
  if (p.group_per_voxel) {
    const uint32_t capacity = (members + TFM_CORR_CAPACITY_STEP - 1) / TFM_CORR_CAPACITY_STEP * TFM_CORR_CAPACITY_STEP;
    p.workgroup = TFM_CORR_GROUP_WORKGROUP;
    // A Kraskov neighbour search may walk past every member (a reference with few distinct
    // values, or a voxel whose series spreads far wider than the reference's, when the k nearest
    // in the max norm are decided by y): enough invocations that their ceil(M / T) searches stay
    // within kKraskovSearchBudget, up to the device's largest workgroup (beyond, check_device_fits
    // refuses devices with a loop limit; others have none and run the plan as it is). Spearman
    // and Kendall comparing every pair likewise (M^2 / T comparisons an invocation), with room
    // for the voxel's other loops.
    const bool counting = pairs_compared(measure, members);
    const bool kraskov = measure == CorrelationMeasure::MiKraskov || measure == CorrelationMeasure::MiCoefficient;
    if (kraskov) {
      const uint64_t point = kraskov_point_loops(members, params.k);
      while (p.workgroup * 2 <= max_workgroup &&
             (members + p.workgroup - 1) / p.workgroup * point > kKraskovSearchBudget)
        p.workgroup *= 2;
      p.search_loops = (members + p.workgroup - 1) / p.workgroup * point;
    } else if (counting) {
      const uint64_t budget = TFM_CORR_LOOP_BUDGET - 4 * TFM_CORR_CAPACITY_STEP;
      const uint64_t walks = (uint64_t(members) * members + budget - 1) / budget;
      p.workgroup = uint32_t(std::max<uint64_t>(p.workgroup, std::bit_ceil(walks)));
    }
    p.region_floats = capacity;
    if (measure == CorrelationMeasure::MiBinned) regions = 0;  // the histogram needs no series storage
  } else {
    p.region_floats = TFM_CORR_INVOCATION_WORKGROUP * TFM_CORR_SLICE_STRIDE;
    if (measure == CorrelationMeasure::MiKraskov || measure == CorrelationMeasure::MiCoefficient)
      p.search_loops = members * kraskov_point_loops(members, params.k);
  }
  p.shared_floats = std::max(1u, regions * p.region_floats);
  p.shared_bytes = uint64_t(p.shared_floats) * 4 + uint64_t(p.workgroup) * 16 + 16;  // s_work, s_reduce, s_counts
  if (measure == CorrelationMeasure::MiBinned) p.shared_bytes += (TFM_CORR_JOINT_WORDS + 2 * TFM_CORR_MAX_BINS) * 4;
  if (measure == CorrelationMeasure::Spearman) p.shared_bytes += 2 * gpu::kFixedSlotBytes;
  return p;
}

}  // namespace

uint32_t CorrelationKernel::max_workgroup(const Context& ctx) {
  const VkPhysicalDeviceLimits& limits = ctx.limits();
  return std::min({kMaxWorkgroup, limits.maxComputeWorkGroupInvocations, limits.maxComputeWorkGroupSize[0]});
}

std::string CorrelationKernel::strategy(const CorrelationParams& params, uint32_t member_count,
                                        uint32_t max_workgroup) {
  const Plan p = make_plan(params, member_count, max_workgroup);
  if (params.measure == CorrelationMeasure::Pearson) return "one invocation per voxel, one shifted pass over the members";
  if (params.measure == CorrelationMeasure::MiBinned)
    return p.group_per_voxel ? "one workgroup per voxel, shared-memory joint histogram"
                             : member_count <= TFM_CORR_INVOCATION_MAX_MEMBERS
                                   ? "one invocation per voxel, pairwise bin counts"
                                   : "one invocation per voxel, y-bin counts per x bin";
  if (pairs_compared(params.measure, member_count))
    return p.group_per_voxel ? "one workgroup per voxel, every pair compared" : "one invocation per voxel, every pair compared";
  return p.group_per_voxel ? "one workgroup per voxel, shared-memory merge sort"
                           : "one invocation per voxel, merge sort in a shared-memory slice";
}

uint32_t CorrelationKernel::workgroup_size(const CorrelationParams& params, uint32_t member_count,
                                          uint32_t max_workgroup) {
  return make_plan(params, member_count, max_workgroup).workgroup;
}

uint64_t CorrelationKernel::shared_memory_bytes(const CorrelationParams& params, uint32_t member_count,
                                               uint32_t max_workgroup) {
  return make_plan(params, member_count, max_workgroup).shared_bytes;
}

double CorrelationKernel::error_bound(const CorrelationParams& params, uint32_t member_count, uint32_t max_workgroup) {
  constexpr double eps = 0x1p-24;
  // Conversions to float, a division (2.5 ulp in Vulkan), square roots and exp, with margin.
  constexpr double final_ops = 64 * eps;
  const CorrelationMeasure m = params.measure;
  // Spearman and Kendall sum exact integers.
  if (m == CorrelationMeasure::Spearman || m == CorrelationMeasure::Kendall) return final_ops;
  if (m == CorrelationMeasure::Pearson) {
    // One pass (shaders/correlation_pearson.comp) with Q = M (mean - y0)^2 <= L syy, so
    // S2 = sum d^2 = syy + Q <= (L + 1) syy. Compensated sums err by <= 2 eps times their terms'
    // magnitudes (M eps^2 is negligible up to kMaxCorrelationMembers), each term by its own
    // roundings: S2 by 5 eps S2; S1 = sum d by 3 eps sum |d| <= 3 eps sqrt(M S2), so Q = S1^2 / M
    // by 6 eps sqrt(Q S2) plus 3.5 eps Q for its division (2.5 ulp) and product; the difference
    // by eps syy. Half of syy's relative error reaches r through sqrt(syy). sxy = sum x d errs by
    // 3 eps sqrt(sxx S2), and by the float x's sum (<= eps / 2 sqrt(M sxx)) times the shift
    // sqrt(Q / M): eps / 2 sqrt(L) sqrt(sxx syy). The second pass (Q beyond L syy) is the
    // two-pass formula, well within this.
    const double l = TFM_CORR_PEARSON_SHIFT_LIMIT;
    const double syy = 5 * (l + 1) + 6 * std::sqrt(l * (l + 1)) + 3.5 * l + 1;
    const double sxy = 3 * std::sqrt(l + 1) + std::sqrt(l) / 2;
    return (syy / 2 + sxy) * eps + final_ops;
  }
  // A float sum of n terms of magnitude <= t errs by <= n eps (n t) at worst; per member (the
  // mean) n eps t. n is the longest chain of additions: one invocation's members, then the
  // workgroup's partials in order.
  const Plan p = make_plan(params, member_count, max_workgroup);
  const double additions =
      p.group_per_voxel ? std::ceil(double(member_count) / p.workgroup) + p.workgroup : double(member_count);
  const double ln_m = std::log(double(member_count));
  // |ln c_xy - ln c_x - ln c_y| <= 3 ln M; |digamma(n_x + 1) + digamma(n_y + 1)| <= 2 (ln M + 1).
  const double term = m == CorrelationMeasure::MiBinned ? 3 * ln_m : 2 * (ln_m + 1);
  // Plus the tabulated values (relative eps each) and the offset (<= 2 ln M + 1) in float.
  const double mi = (additions + 1) * eps * term + 2 * eps * (2 * ln_m + 1) + final_ops;
  return m == CorrelationMeasure::MiCoefficient ? std::sqrt(2 * mi) + final_ops : mi;
}

namespace {
// record()'s chunks of an ensemble beyond one texel view: multiples of this many voxels.
constexpr uint64_t kRecordChunkAlign = 64;
}  // namespace

struct CorrelationKernel::Impl {
  Impl(Context& c, uint32_t max_wg) : ctx(c), max_workgroup(CorrelationKernel::max_workgroup(c)) {
    if (max_wg) max_workgroup = std::min(max_wg, max_workgroup);
  }
  Context& ctx;
  uint32_t max_workgroup;  // what the plans are made with
  // Pipelines by (shader, strategy, workgroup, region size, coefficient, layout), built on first
  // use and kept. The workgroup is part of the key: the Kraskov measures' grows with k at the
  // same member count (and so the same region).
  std::map<std::tuple<std::string, bool, uint32_t, uint32_t, bool, bool>, SharedPipeline> pipelines;

  // `member_major`: the series' layout (uploaded chunks: member-major unless one workgroup per
  // voxel; device-resident ensembles: member-major).
  const ComputePipeline& pipeline(const Plan& p, bool member_major) {
    auto& slot = pipelines[{p.shader, p.group_per_voxel, p.workgroup, p.region_floats, p.coefficient, member_major}];
    if (!slot) {
      PipelineDesc desc;
      desc.shader = p.shader;
      desc.binding_counts = gpu::to_vector(kBindingCounts);
      desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(),
                                                 {TFM_CORR_BINDING_ENSEMBLE, TFM_CORR_BINDING_REF_VALUES});
      desc.push_constant_bytes = sizeof(gpu::CorrelationPush);
      desc.workgroup_size = p.workgroup;
      desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, p.workgroup},
                                        {TFM_CORR_SPEC_GROUP_PER_VOXEL, p.group_per_voxel ? 1u : 0u},
                                        {TFM_CORR_SPEC_REGION_FLOATS, p.region_floats},
                                        {TFM_CORR_SPEC_SHARED_FLOATS, p.shared_floats},
                                        {TFM_CORR_SPEC_COEFFICIENT, p.coefficient ? 1u : 0u},
                                        {TFM_CORR_SPEC_MEMBER_MAJOR, member_major ? 1u : 0u}});
      desc.spirv = shader_spirv(desc.shader);
      slot = shared_pipeline(ctx, desc);
    }
    return *slot;
  }

  // A device buffer kept between compute() calls, grown when a call needs more: a new allocation
  // of the ensemble's size on every call cost as much as the whole field's computation.
  Buffer& kept(Buffer& buffer, uint64_t bytes, const char* name) {
    if (!buffer || buffer.size() < bytes) {
      buffer = Buffer();  // the old one first: the footprint stays bounded
      buffer = Buffer(ctx, bytes, MemoryUsage::Device, name);
    }
    return buffer;
  }
  Buffer series, result;
  Buffer recorded_series;  // record()'s chunks of an ensemble beyond one texel view
  std::vector<float> gathered;  // a chunk laid out on the host, when it cannot go up member by member

  static constexpr auto kBindingCounts =
      gpu::binding_counts({TFM_CORR_BINDING_ENSEMBLE, TFM_CORR_BINDING_OUT, TFM_CORR_BINDING_REF_VALUES,
                           TFM_CORR_BINDING_REF_ORDER, TFM_CORR_BINDING_REF_GROUP, TFM_CORR_BINDING_TABLE});
};

namespace {

// Puts voxels [v0, v0 + n) of `ens` into `series` in the chunk layout of the strategy
// (shaders/correlation_layout.h). A member-major chunk of every voxel is the caller's array itself
// and goes up in one transfer. Other member-major chunks go member by member: each member's run of
// n values goes up straight from the caller's array where it is
// large enough to be copied in place (buffer.h), else the runs are packed into `gathered` and go
// up together (one transfer instead of M small ones). Voxel-major chunks are transposed on the
// host into `gathered`.
void upload_chunk(Context& ctx, const EnsembleView& ens, uint64_t v0, uint32_t n, bool voxel_major,
                  std::vector<float>& gathered, Buffer& series) {
  const uint32_t members = ens.member_count;
  const uint64_t run_bytes = uint64_t(n) * sizeof(float);
  if (!voxel_major && n == ens.voxel_count) {  // the whole ensemble: already the chunk's layout
    upload(ctx, series, ens.values, run_bytes * members);
    return;
  }
  if (!voxel_major && ctx.host_import() && run_bytes >= kHostImportMinBytes) {
    for (uint32_t m = 0; m < members; ++m)
      upload(ctx, series, ens.values + m * ens.voxel_count + v0, run_bytes, m * run_bytes);
    return;
  }
  gathered.resize(uint64_t(n) * members);
  if (voxel_major)
    gather_series(ens, v0, n, gathered.data());
  else
    for (uint32_t m = 0; m < members; ++m)
      std::memcpy(gathered.data() + uint64_t(m) * n, ens.values + m * ens.voxel_count + v0, run_bytes);
  upload(ctx, series, gathered.data(), run_bytes * members);
}

}  // namespace

namespace {

constexpr uint64_t kDefaultDeviceBytes = 256ull << 20;

// The whole member-major ensemble as one device field over its host memory, or null where the
// device reads a copy (DeviceField::in_host_memory) or it takes more than one buffer.
std::unique_ptr<DeviceField> ensemble_in_host_memory(Context& ctx, const EnsembleView& ens) {
  const uint64_t values = ens.voxel_count * ens.member_count;
  std::optional<DeviceField> field =
      DeviceField::in_host_memory(ctx, std::span<const float>(ens.values, values), "correlation ensemble", values);
  if (!field || field->chunk_count() != 1) return nullptr;
  return std::make_unique<DeviceField>(std::move(*field));
}

// The region and histogram sizes are fixed by the member count; a device with less shared memory
// or smaller workgroups than they need cannot run this measure at this size.
void check_device_fits(const Context& ctx, const Plan& plan, const std::string& name, uint32_t members) {
  const VkPhysicalDeviceLimits& limits = ctx.limits();
  const std::string what = name + " with " + std::to_string(members) + " members needs ";
  if (plan.shared_bytes > limits.maxComputeSharedMemorySize)
    throw std::runtime_error(what + std::to_string(plan.shared_bytes) + " bytes of workgroup shared memory; the device has " +
                             std::to_string(limits.maxComputeSharedMemorySize) + " (maxComputeSharedMemorySize)");
  const uint32_t max_workgroup = std::min(limits.maxComputeWorkGroupInvocations, limits.maxComputeWorkGroupSize[0]);
  if (plan.workgroup > max_workgroup)
    throw std::runtime_error(what + "workgroups of " + std::to_string(plan.workgroup) + " invocations; the device allows " +
                             std::to_string(max_workgroup) + " (maxComputeWorkGroupInvocations, maxComputeWorkGroupSize[0])");
  if (const uint64_t limit = ctx.loop_iteration_limit(); limit && plan.search_loops * 65535 > kKraskovSearchBudget * limit)
    throw std::runtime_error(what + "up to " + std::to_string(plan.search_loops) +
                             " loop iterations in one shader invocation for its neighbour searches; this device's driver "
                             "ends an invocation's loops after " + std::to_string(limit) +
                             " (llvmpipe): use a smaller --k or fewer members, or another Vulkan device");
}

// Groups for one voxel per workgroup or invocation, never more (shaders/correlation_common.glsl):
// rows of at most maxComputeWorkGroupCount[0] groups (the limits guarantee 65535 rows).
Groups correlation_groups(const Context& ctx, const Plan& plan, uint64_t voxels) {
  const uint64_t groups = plan.group_per_voxel ? voxels : (voxels + plan.workgroup - 1) / plan.workgroup;
  const uint64_t groups_x = std::min<uint64_t>(groups, ctx.limits().maxComputeWorkGroupCount[0]);
  return {uint32_t(groups_x), uint32_t((groups + groups_x - 1) / groups_x)};
}

gpu::CorrelationPush make_push(const CorrelationReference& ref) {
  gpu::CorrelationPush push{};
  push.member_count = ref.members;
  push.param = ref.params.measure == CorrelationMeasure::MiBinned ? ref.params.bins : ref.params.k;
  push.flags = (ref.constant ? TFM_CORR_FLAG_REF_CONSTANT : 0u) | (ref.tied_pairs > 0 ? TFM_CORR_FLAG_REF_TIES : 0u);
  push.ref_lo = ref.lo;
  push.ref_hi = ref.hi;
  push.ref_norm = float(ref.norm);
  push.ref_tied_pairs = uint32_t(ref.tied_pairs);
  push.mi_offset = float(ref.mi_offset);
  return push;
}

}  // namespace

CorrelationKernel::CorrelationKernel(Context& ctx, uint32_t max_workgroup)
    : impl_(std::make_unique<Impl>(ctx, max_workgroup)) {}
CorrelationKernel::~CorrelationKernel() = default;

void CorrelationKernel::prepare(const CorrelationParams& params, uint32_t member_count) {
  validate_correlation_params(params, member_count);  // before the series' allocation
  // lavapipe compiles a pipeline's code at its first dispatch, not at its creation: so one voxel
  // (its series the reference itself) goes through compute(), the path the caller's work takes.
  std::vector<float> series(member_count);
  for (uint32_t m = 0; m < member_count; ++m) series[m] = float(m);
  compute(EnsembleView{series.data(), member_count, 1}, series, params);
}

std::vector<float> CorrelationKernel::compute(const EnsembleView& ens, std::span<const float> reference,
                                              const CorrelationParams& params, const CorrelationProgress& progress,
                                              uint64_t max_device_bytes) {
  const std::string name = correlation_measure_name(params.measure);
  validate_correlation_inputs(ens, reference, params);
  const uint32_t members = ens.member_count;
  const uint64_t voxels = ens.voxel_count;
  const CorrelationReference ref = prepare_correlation_reference(reference, params);
  check_memory(voxels * sizeof(float), name + ": the field of " + std::to_string(voxels) + " voxels");
  std::vector<float> out(voxels, std::numeric_limits<float>::quiet_NaN());
  if (ref.has_nan) {  // NaN at every voxel (kernels/correlation.h)
    if (progress) progress(voxels, voxels);
    return out;
  }

  Context& ctx = impl_->ctx;
  const Plan plan = make_plan(params, members, impl_->max_workgroup);
  const VkPhysicalDeviceLimits& limits = ctx.limits();
  check_device_fits(ctx, plan, name, members);
  const ComputePipeline& pipeline = impl_->pipeline(plan, !plan.group_per_voxel);

  // Device memory: the reference buffers, then per voxel its series twice (staging and device
  // copy) and its result twice (device and readback). Where that memory is the host's, the default
  // takes at most half of what the memory budget leaves (the rest for a second pass's field), and
  // what the chunks take is checked with the budget: 256 MiB of chunks took a 12 x 7 M voxel run
  // 33 % past --max-memory.
  const uint64_t fixed_bytes = uint64_t(members) * 16 + 16;
  const uint64_t voxel_bytes = uint64_t(members) * 8 + 8;
  const bool host_memory = device_memory_is_host(ctx);
  uint64_t budget = max_device_bytes ? max_device_bytes : kDefaultDeviceBytes;
  if (!max_device_bytes && host_memory) {
    const uint64_t held = resident_memory(), limit = memory_budget().bytes;
    budget = std::clamp<uint64_t>(limit > held ? (limit - held) / 2 : 0, fixed_bytes + voxel_bytes, budget);
  }
  if (budget < fixed_bytes + voxel_bytes)
    throw std::invalid_argument(name + ": max_device_bytes = " + std::to_string(budget) + " is too small; one voxel of " +
                                std::to_string(members) + " members needs " + std::to_string(fixed_bytes + voxel_bytes));
  // A chunk's series are one texel view: at most maxTexelBufferElements values.
  const uint64_t view_voxels = std::min({ctx.max_buffer_bytes() / (uint64_t(members) * sizeof(float)),
                                         uint64_t(limits.maxTexelBufferElements) / members, voxels});
  uint64_t chunk = std::min((budget - fixed_bytes) / voxel_bytes, view_voxels);
  // A member-major ensemble in one view is read where it is on a CPU device (its memory is host
  // memory anyway: DeviceField::in_host_memory), instead of copied into a buffer of its own; then
  // only the results take memory, so the default budget does not limit the chunk.
  const std::unique_ptr<DeviceField> in_place =
      !plan.group_per_voxel && (chunk == voxels || (!max_device_bytes && view_voxels == voxels))
          ? ensemble_in_host_memory(ctx, ens)
          : nullptr;
  if (in_place) chunk = voxels;
  const std::string chunks = name + ": " + (in_place ? "the results of " + std::to_string(voxels) + " voxels"
                                                     : "chunks of " + std::to_string(chunk) + " voxels of " +
                                                           std::to_string(members) + " members");
  check_device_memory(ctx, fixed_bytes + chunk * (in_place ? 8 : voxel_bytes), chunks);

  Buffer values = make_buffer<float>(ctx, ref.values, "correlation reference values");
  Buffer order = make_buffer<uint32_t>(ctx, ref.order, "correlation reference order");
  Buffer group = make_buffer<uint32_t>(ctx, ref.group, "correlation reference tie groups");
  Buffer table = make_buffer<float>(ctx, ref.table, "correlation count table");
  const Buffer& series = in_place ? in_place->chunk(0)
                                  : impl_->kept(impl_->series, chunk * members * sizeof(float), "correlation ensemble chunk");
  Buffer& result = impl_->kept(impl_->result, chunk * sizeof(float), "correlation result chunk");
  gpu::CorrelationPush push = make_push(ref);
  for (uint64_t v0 = 0; v0 < voxels; v0 += chunk) {
    const uint32_t n = uint32_t(std::min(chunk, voxels - v0));
    // Each transfer waits for its copies, so the chunk is on the device before the kernel reads it
    // (and the previous chunk's kernel, waited for below, has finished reading `series`).
    if (!in_place) upload_chunk(ctx, ens, v0, n, plan.group_per_voxel, impl_->gathered, impl_->series);
    push.voxel_count = n;
    push.member_stride = n;  // of a member-major chunk (upload_chunk)
    CommandBatch batch(ctx);
    batch.dispatch(pipeline,
                   {Binding::texels(series, VK_FORMAT_R32_SFLOAT, 0, uint64_t(n) * members * sizeof(float)), result,
                    Binding::texels(values, VK_FORMAT_R32_SFLOAT), order, group, table},
                   push, correlation_groups(ctx, plan, n));
    batch.submit_and_wait();
    readback(ctx, result, out.data() + v0, uint64_t(n) * sizeof(float));
    if (progress) progress(v0 + n, voxels);
  }
  return out;
}

void record_correlation_tables(CommandBatch& batch, Context& ctx, const CorrelationReference& ref,
                               CorrelationTables& tables) {
  auto write = [&](Buffer& buffer, const void* data, uint64_t bytes, const char* name) {
    const uint64_t size = std::max<uint64_t>(bytes, 4);
    if (buffer.size() < size) buffer = Buffer(ctx, size, MemoryUsage::Device, name);
    if (bytes) batch.update(buffer, 0, data, bytes);
  };
  write(tables.values, ref.values.data(), ref.values.size() * sizeof(float), "correlation reference values");
  write(tables.order, ref.order.data(), ref.order.size() * sizeof(uint32_t), "correlation reference order");
  write(tables.group, ref.group.data(), ref.group.size() * sizeof(uint32_t), "correlation reference tie groups");
  write(tables.table, ref.table.data(), ref.table.size() * sizeof(float), "correlation count table");
}

void CorrelationKernel::check_record(const DeviceEnsemble& ensemble, const CorrelationParams& params, uint32_t members,
                                     const Buffer& out) const {
  const std::string name = correlation_measure_name(params.measure);
  const Context& ctx = impl_->ctx;
  const uint64_t voxels = ensemble.voxel_count();
  const uint64_t value_bytes = field_format_bytes(ensemble.format);
  if (!ensemble.buffer && ensemble.images.size() != members)
    throw std::invalid_argument(name + ": " + std::to_string(ensemble.images.size()) + " member images for a reference of " +
                                std::to_string(members) + " members");
  if (voxels == 0) throw std::invalid_argument(name + ": no voxels");
  if (voxels > std::numeric_limits<uint32_t>::max())
    throw std::invalid_argument(name + ": " + std::to_string(voxels) + " voxels; one recording takes at most 2^32 - 1");
  if (ensemble.buffer && ensemble.buffer->size() < uint64_t(members) * voxels * value_bytes)
    throw std::invalid_argument(name + ": the ensemble buffer holds " + std::to_string(ensemble.buffer->size()) +
                                " bytes, " + std::to_string(members) + " members x " + std::to_string(voxels) +
                                " voxels of " + field_format_name(ensemble.format) + " need " +
                                std::to_string(uint64_t(members) * voxels * value_bytes));
  for (const CommandBatch::HostImage& image : ensemble.images)
    if (image.image == VK_NULL_HANDLE) throw std::invalid_argument(name + ": a member image is VK_NULL_HANDLE");
  require_field_format(ctx, ensemble.format, name + " ensemble", /*quads=*/false);
  if (out.size() < voxels * sizeof(float))
    throw std::invalid_argument(name + ": the output buffer holds fewer than " + std::to_string(voxels) + " floats");
  if (uint64_t(members) * kRecordChunkAlign > ctx.limits().maxTexelBufferElements)
    throw std::invalid_argument(name + ": " + std::to_string(members) + " members: " +
                                std::to_string(kRecordChunkAlign) + " voxels of them exceed one texel view of this "
                                "device (maxTexelBufferElements " +
                                std::to_string(ctx.limits().maxTexelBufferElements) + ")");
}

uint64_t CorrelationKernel::min_chunk_bytes(uint32_t members, FieldFormat format) {
  return kRecordChunkAlign * members * field_format_bytes(format);
}

void CorrelationKernel::record(CommandBatch& batch, const DeviceEnsemble& ensemble, const CorrelationReference& ref,
                               const CorrelationTables& tables, Buffer& out, uint64_t max_chunk_voxels,
                               const Buffer* chunk_memory) {
  const std::string name = correlation_measure_name(ref.params.measure);
  const uint32_t members = ref.members;
  const uint64_t voxels = ensemble.voxel_count();
  Context& ctx = impl_->ctx;
  check_record(ensemble, ref.params, members, out);
  if (ref.has_nan) {  // NaN at every voxel (kernels/correlation.h)
    Buffer view = Buffer::adopt(ctx, out.handle(), out.offset(), voxels * sizeof(float), "correlation output");
    batch.fill(view, 0x7fc00000u);
    return;
  }
  const Plan plan = make_plan(ref.params, members, impl_->max_workgroup);
  check_device_fits(ctx, plan, name, members);
  gpu::CorrelationPush push = make_push(ref);
  const ComputePipeline& pipeline = impl_->pipeline(plan, true);  // member-major whatever the strategy
  // The kernels read every format through a texel view of it: the stored texels, converted by the
  // device as a fetch from a field of that format is.
  const VkFormat texel_format = voxel_texel_format(ensemble.format);
  const uint64_t value_bytes = field_format_bytes(ensemble.format);
  uint64_t chunk = std::min<uint64_t>(ctx.limits().maxTexelBufferElements / members, voxels);
  if (max_chunk_voxels) chunk = std::min(chunk, max_chunk_voxels);
  if (ensemble.buffer && chunk == voxels) {  // the whole ensemble is one texel view: read in place
    push.voxel_count = uint32_t(voxels);
    push.member_stride = uint32_t(voxels);
    batch.dispatch(pipeline,
                   {Binding::texels(*ensemble.buffer, texel_format, 0, uint64_t(members) * voxels * value_bytes), out,
                    Binding::texels(tables.values, VK_FORMAT_R32_SFLOAT), tables.order, tables.group, tables.table},
                   push, correlation_groups(ctx, plan, voxels));
    return;
  }
  // Beyond one texel view, and from images: voxels [v0, v0 + n) of every member copied on the
  // device (a buffer region, or up to five image regions, per member) into a member-major chunk of
  // the kernel's that is one view, then the kernel on it into out's range. Chunks of a multiple of
  // kRecordChunkAlign voxels keep out's ranges at storage-buffer offset alignment (the device's is
  // at most 256 bytes).
  const uint64_t memory = chunk_memory ? chunk_memory->size() : kRecordChunkBytes;
  if (memory < min_chunk_bytes(members, ensemble.format))
    throw std::invalid_argument(name + ": chunk memory of " + std::to_string(memory) + " bytes; " +
                                std::to_string(members) + " members need at least " +
                                std::to_string(min_chunk_bytes(members, ensemble.format)));
  chunk = std::min(chunk, memory / (members * value_bytes));
  chunk = std::max<uint64_t>(kRecordChunkAlign, chunk / kRecordChunkAlign * kRecordChunkAlign);
  const Buffer& series = chunk_memory ? *chunk_memory
                                      : impl_->kept(impl_->recorded_series, chunk * members * value_bytes,
                                                    "recorded correlation chunk");
  if (!ensemble.buffer) batch.begin_image_copies(ensemble.images);
  for (uint64_t v0 = 0; v0 < voxels; v0 += chunk) {
    const uint64_t n = std::min(chunk, voxels - v0);
    if (v0 > 0) batch.barrier();  // the last chunk's kernel read `series` before these copies write it
    for (uint32_t m = 0; m < members; ++m) {
      const uint64_t at = uint64_t(m) * n * value_bytes;
      if (ensemble.buffer)
        batch.copy(*ensemble.buffer, (uint64_t(m) * voxels + v0) * value_bytes, series, at, n * value_bytes);
      else
        batch.copy_image_voxels(ensemble.images[m], ensemble.extent, uint32_t(value_bytes), v0, n, series, at);
    }
    batch.barrier();  // the chunk's copies before the kernel reads them
    push.voxel_count = uint32_t(n);
    push.member_stride = uint32_t(n);
    const Buffer range = Buffer::adopt(ctx, out.handle(), out.offset() + v0 * sizeof(float), n * sizeof(float),
                                       "correlation output range");
    batch.dispatch(pipeline,
                   {Binding::texels(series, texel_format, 0, uint64_t(members) * n * value_bytes), range,
                    Binding::texels(tables.values, VK_FORMAT_R32_SFLOAT), tables.order, tables.group, tables.table},
                   push, correlation_groups(ctx, plan, n));
  }
  if (!ensemble.buffer) batch.end_image_copies(ensemble.images);
  batch.barrier();  // the kernel's reads of the chunk before any later copy into it
}

}  // namespace tfm
