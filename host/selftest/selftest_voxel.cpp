// Self-test cases of the voxel-pair kernels: assemble_normal_equations (every mode and atomic
// width, chunked fields, TF sizes past shared memory, exact fixed-point totals), voxel_loss,
// residual_map, field_histogram and field_pair_read (the bench's read bound), each against its
// CPU reference.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>

#include <glm/gtc/packing.hpp>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/assemble_normal_equations.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/histogram.h"
#include "tfmatch/kernels/read_bound.h"
#include "tfmatch/kernels/residual_map.h"
#include "tfmatch/kernels/voxel_loss.h"
#include "tfmatch/reference/histogram_cpu.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/reference/residual_map_cpu.h"
#include "tfmatch/selftest/selftest_support.h"
#include "tfmatch/shaders/render_layout.h"

namespace tfm::selftest {
namespace {

const FieldRange kOptRange{3.0, 8.0};

struct AssembleCase {
  size_t voxels;
  uint32_t tf_size;
  ReductionMode mode = ReductionMode::Auto;
  AtomicWidth atomics = AtomicWidth::Auto;
  uint64_t chunk_voxels = 0;    // field chunks (0: one)
  uint32_t range_quads = 0;     // texel ranges of the chunks (0: the device's)
};

// Bounds: every term the kernel adds is non-negative, so per entry |device - reference| <= (float
// rounding of at most 4 operations per term, 4 * 2^-24 relative) * entry + (fixed-point
// truncation, < 2^-32 per term) * terms; 1e-6 relative covers the first with margin, the second
// is the absolute part. The voxel count is exact, and so is every fixed-point slot: the device must
// form the same integer totals as the CPU's exact emulation. Every case also sums the loss before
// optimization (the second field on the reference TF's 17 entries), so it is checked on every
// path, chunking and range: within 1e-6 relative plus 2^-31 per voxel of before_loss_cpu.
// The device's system against the reference's: the voxel count exactly, every entry of M, S^T b
// and b^T b within 1e-6 relative plus `abs_bound`.
void check_system(Check& check, const NormalEquations& g, const NormalEquations& r, double abs_bound) {
  check.equal("voxel count", 0, double(g.voxels), double(r.voxels));
  auto near = [&](const char* what, size_t j, double device, double reference) {
    check.near(what, j, device, reference, 1e-6 * std::abs(reference) + abs_bound);
  };
  for (size_t j = 0; j < r.diag.size(); ++j) near("M diagonal", j, g.diag[j], r.diag[j]);
  for (size_t j = 0; j < r.off.size(); ++j) near("M off-diagonal", j, g.off[j], r.off[j]);
  for (Eigen::Index j = 0; j < r.rhs.rows(); ++j)
    for (int ch = 0; ch < 4; ++ch) near("S^T b (4j+c)", size_t(4 * j + ch), g.rhs(j, ch), r.rhs(j, ch));
  for (int ch = 0; ch < 4; ++ch) near("b^T b channel", size_t(ch), g.btb[ch], r.btb[ch]);
}

// Every 32.32 fixed-point slot the device formed against the CPU's exact integer totals.
void check_fixed_point(Check& check, const std::vector<uint64_t>& device, const std::vector<uint64_t>& exact) {
  check.require(device.size() == exact.size(), "the device returned another number of slots");
  for (size_t k = 0; k < exact.size() && k < device.size(); ++k)
    check.equal("fixed-point slot (units of 2^-32)", k, double(int64_t(device[k] - exact[k])), 0.0);
}

void assemble(Context& ctx, Check& check, const AssembleCase& c) {
  const std::string missing =
      reduction_unavailable(ctx, {c.mode, c.atomics}, c.tf_size, uint64_t(TFM_ASSEMBLE_SLOTS(c.tf_size)) * 8,
                            kAssemblePrivateMaxBins);
  if (!missing.empty()) return check.skip(missing);
  const FieldPair p = random_pair(c.voxels, 1234u + uint32_t(c.voxels), kOptRange, c.tf_size);
  const TransferFunction ref_tf = random_tf(17, 99);
  const FieldMapping ref_map = make_mapping({0.0, 1.0}, 17), opt_map = make_mapping(kOptRange, c.tf_size);
  const FieldMapping before_map = make_mapping(kOptRange, 17);
  DeviceField ref(ctx, p.ref, "selftest reference", c.chunk_voxels), opt(ctx, p.opt, "selftest field", c.chunk_voxels);
  if (c.chunk_voxels) check.require(ref.chunk_count() > 1, "the field is not split into chunks");
  Buffer tf = upload_tf(ctx, ref_tf, "selftest reference TF");
  GpuNormalEquations gpu(ctx, c.tf_size, {c.mode, c.atomics, 0, c.range_quads});
  if (c.mode != ReductionMode::Auto) check.require(gpu.kernel().mode() == c.mode, "the kernel chose another path");
  if (c.atomics != AtomicWidth::Auto)
    check.require(gpu.kernel().int64_atomics() == (c.atomics == AtomicWidth::Bits64), "the kernel chose other atomics");
  const uint32_t private_slots = private_limit(ctx, kPrivateHistogramSlots);
  if (c.mode == ReductionMode::Private && c.tf_size > private_slots / 11)
    check.require(assemble_term_passes(c.mode, c.tf_size, private_slots).size() > 1,
                  "a histogram beyond the private budget is not split into term passes");
  gpu.add(ref, opt, ref_map, opt_map, tf, &before_map);
  const NormalEquations g = gpu.result();
  const NormalEquations r = assemble_normal_equations_cpu(p.ref, p.opt, ref_map, opt_map, ref_tf);
  check_system(check, g, r, double(c.voxels) * std::ldexp(1.0, -32) + 1e-12);
  check_fixed_point(check, gpu.fixed_point_slots(),
                    assemble_normal_equations_fixed_point(p.ref, p.opt, ref_map, opt_map, ref_tf, &before_map));
  check.require(g.before.has_value(), "the assembly returned no loss before optimization");
  if (g.before) {
    const std::array<double, 4> want = before_loss_cpu(p.ref, p.opt, ref_map, before_map, ref_tf);
    for (int ch = 0; ch < 4; ++ch)
      check.near("loss before, channel", size_t(ch), (*g.before)[ch], want[ch],
                 1e-6 * want[ch] + double(g.voxels) * std::ldexp(1.0, -31));
  }
}

// The second field as an embedder may store it (DeviceField::adopt): float16, unorm16 or unorm8
// codes in a buffer, read by texel fetches as the stored numbers. Skipped, saying which texel
// format is missing, where the device cannot read the format (unorm16 is optional in Vulkan).
// The reference is the assembly in double of the numbers the codes stand for: float16 converts
// exactly, so the bounds and the exact fixed-point totals are those of float32 fields; a unorm
// code c stands for c / (2^b - 1), which a device may give as the rounded quotient or as c times
// the rounded reciprocal, one float ulp (<= 2^-24 on [0, 1]) apart. A value moved by d moves each
// of its hat weights by at most (N - 1) d, so each M entry (two weights) and S^T b entry (a
// weight times b in [-0.1, 1.1]) by at most 2.2 (N - 1) d per voxel: that, per voxel, is added
// to the bounds, and the fixed-point totals are not compared.
void assemble_stored(Context& ctx, Check& check, FieldFormat format, size_t voxels) {
  if (std::string why = field_format_unsupported(ctx, format); !why.empty()) return check.skip(why);
  const uint32_t n = 64;
  const FieldPair p = random_pair(voxels, 4321u + uint32_t(voxels), {0.0, 1.0}, n);
  const bool unorm = format != FieldFormat::Float16;
  const double code_max = format == FieldFormat::Unorm16 ? 65535.0 : 255.0;
  std::vector<uint8_t> stored(voxels * field_format_bytes(format));
  std::vector<float> values(voxels);  // what each stored code stands for
  for (size_t i = 0; i < voxels; ++i) {
    if (!unorm) {
      const uint16_t h = glm::packHalf1x16(p.opt[i]);
      std::memcpy(&stored[2 * i], &h, 2);
      values[i] = glm::unpackHalf1x16(h);
      continue;
    }
    // No NaN in a unorm: a field without missing values, clamped to [0, 1] (values 10% past it
    // land on the ends, as off-range values do).
    const double v = std::isfinite(p.opt[i]) ? std::clamp(double(p.opt[i]), 0.0, 1.0) : 0.5;
    const uint32_t code = uint32_t(std::lround(v * code_max));
    if (format == FieldFormat::Unorm16) {
      const uint16_t c16 = uint16_t(code);
      std::memcpy(&stored[2 * i], &c16, 2);
    } else {
      stored[i] = uint8_t(code);
    }
    values[i] = float(double(code) / code_max);
  }
  const TransferFunction ref_tf = random_tf(17, 98);
  const FieldMapping ref_map = make_mapping({0.0, 1.0}, 17), opt_map = make_mapping({0.0, 1.0}, n);
  Buffer memory(ctx, std::max<uint64_t>(4, (stored.size() + 3) / 4 * 4), MemoryUsage::Device, "selftest stored field");
  upload(ctx, memory, stored.data(), stored.size());
  DeviceField ref(ctx, p.ref, "selftest reference");
  const DeviceField opt =
      DeviceField::adopt(ctx, memory.handle(), memory.offset(), voxels, "selftest stored field", 0, format);
  Buffer tf = upload_tf(ctx, ref_tf, "selftest reference TF");
  GpuNormalEquations gpu(ctx, n);
  gpu.add(ref, opt, ref_map, opt_map, tf);
  const NormalEquations g = gpu.result();
  const NormalEquations r = assemble_normal_equations_cpu(p.ref, values, ref_map, opt_map, ref_tf);
  const double per_voxel = std::ldexp(1.0, -32) + (unorm ? 2.2 * (n - 1) * std::ldexp(1.0, -24) : 0.0);
  check_system(check, g, r, double(voxels) * per_voxel + 1e-12);
  if (!unorm)
    check_fixed_point(check, gpu.fixed_point_slots(),
                      assemble_normal_equations_fixed_point(p.ref, values, ref_map, opt_map, ref_tf));
}

std::string assemble_name(const AssembleCase& c) {
  std::string s = voxels_name(c.voxels) + ", N=" + std::to_string(c.tf_size) + reduction_name({c.mode, c.atomics});
  if (c.chunk_voxels) s += ", chunks of " + std::to_string(c.chunk_voxels);
  if (c.range_quads) s += ", ranges of " + std::to_string(c.range_quads) + " quads";
  return s;
}

// Reference voxel loss: per channel sums of d^2 and |d|, d = clamp(T_o(F_o)) - clamp(T_r(F_r)).
// Bound per channel: each d is formed in float from values in [-0.1, 1.1] (two products and two
// sums per colour, then a difference: < 6e-7), so d^2 moves by < 2 |d| 6e-7 + 2^-24 < 2e-6 and
// |d| by < 1e-6; each term is truncated to 2^-32 in fixed point. The voxel count is exact.
// With `before`, the pass that also measures the second field shown with the reference TF
// (voxel_losses_gpu), each loss checked the same way.
void voxel_loss(Context& ctx, Check& check, size_t voxels, uint64_t chunk_voxels, bool before) {
  const uint32_t n = 23;
  const FieldPair p = random_pair(voxels, 77u + uint32_t(voxels), kOptRange, n);
  const TransferFunction ref_tf = random_tf(17, 5, -0.1, 1.1), opt_tf = random_tf(n, 6, -0.1, 1.1);
  const FieldMapping ref_map = make_mapping({0.0, 1.0}, 17), opt_map = make_mapping(kOptRange, n);
  const FieldMapping before_map = make_mapping(kOptRange, 17);
  DeviceField ref(ctx, p.ref, "selftest reference", chunk_voxels), opt(ctx, p.opt, "selftest field", chunk_voxels);
  Buffer rtf = upload_tf(ctx, ref_tf, "selftest reference TF"), otf = upload_tf(ctx, opt_tf, "selftest TF");
  VoxelLosses g;
  if (before) g = voxel_losses_gpu(ctx, ref, opt, ref_map, before_map, opt_map, rtf, otf);
  else g.after = voxel_loss_gpu(ctx, ref, opt, ref_map, opt_map, rtf, otf);
  const std::vector<float> rf = ref_tf.as_floats(), of = opt_tf.as_floats();
  auto expect = [&](const VoxelLoss& got, const std::vector<float>& tf, const FieldMapping& map, bool is_before) {
    double squared[4] = {0, 0, 0, 0}, absolute[4] = {0, 0, 0, 0};
    uint64_t counted = 0;
    for (size_t i = 0; i < voxels; ++i) {
      double b[4], v[4];
      if (!classify(rf, ref_map, p.ref[i], b) || !classify(tf, map, p.opt[i], v)) continue;
      ++counted;
      for (int ch = 0; ch < 4; ++ch) {
        squared[ch] += (v[ch] - b[ch]) * (v[ch] - b[ch]);
        absolute[ch] += std::abs(v[ch] - b[ch]);
      }
    }
    check.equal(is_before ? "before: voxel count" : "voxel count", 0, double(got.voxels), double(counted));
    const double per_term = std::ldexp(1.0, -32) + 1e-12;
    for (int ch = 0; ch < 4; ++ch) {
      check.near(is_before ? "before: sum of squares, channel" : "sum of squares, channel", ch, got.squared[ch], squared[ch], double(counted) * (2e-6 + per_term));
      check.near(is_before ? "before: sum of |d|, channel" : "sum of |d|, channel", ch, got.absolute[ch], absolute[ch], double(counted) * (1e-6 + per_term));
    }
  };
  expect(g.after, of, opt_map, false);
  if (before) expect(g.before, rf, before_map, true);
}

// The residual map against residual_map_cpu. Bound: float interpolation and premultiplication
// of values in [0,1] (a few roundings of 2^-24 each) and a float sqrt of a sum <= 4 stay below
// 1e-6. Voxels without data are exactly 0.
void residual(Context& ctx, Check& check, size_t voxels, uint64_t chunk_voxels) {
  const uint32_t n = 64;
  const FieldPair p = random_pair(voxels, 31u + uint32_t(voxels), {20.0, 25.0}, n);
  const TransferFunction ref_tf = random_tf(23, 7), opt_tf = random_tf(n, 8);
  const FieldMapping ref_map = make_mapping({0.0, 1.0}, 23), opt_map = make_mapping({20.0, 25.0}, n);
  DeviceField ref(ctx, p.ref, "selftest reference", chunk_voxels), opt(ctx, p.opt, "selftest field", chunk_voxels);
  DeviceField out(ctx, voxels, "selftest residual", ref.chunk_voxels());
  Buffer rtf = upload_tf(ctx, ref_tf, "selftest reference TF"), otf = upload_tf(ctx, opt_tf, "selftest TF");
  const ResidualMapKernel kernel(ctx);
  CommandBatch batch(ctx);
  kernel.record(batch, ref, opt, ref_map, opt_map, rtf, otf, out);
  batch.submit_and_wait();
  std::vector<float> g(voxels);
  for (size_t c = 0; c < out.chunk_count(); ++c)
    readback(ctx, out.chunk(c), g.data() + out.chunk_begin(c), out.chunk_size(c) * sizeof(float));
  const std::vector<double> expected =
      residual_map_cpu(p.ref, p.opt, ref_tf.as_floats(), ref_map, opt_tf.as_floats(), opt_map);
  for (size_t i = 0; i < voxels; ++i) {
    if (std::isnan(p.ref[i]) || std::isnan(p.opt[i]))
      check.equal("voxel without data", i, g[i], 0.0);
    else
      check.near("voxel", i, g[i], expected[i], 1e-6);
  }
}

// Counts are integers: every counter equals the reference's exactly (values binned with the
// shader's float32 arithmetic, histogram_counter()), and every value is counted once. Values in
// [-0.5, 10.5] around the range [0, 10], NaN every 11th, the range's ends exactly every 23rd and
// 29th.
void histogram(Context& ctx, Check& check, size_t voxels, uint32_t bins, HistogramMode mode, uint64_t chunk_voxels) {
  std::vector<float> values = random_floats(voxels, 91u + uint32_t(voxels) + bins, -0.5f, 10.5f);
  for (size_t i = 3; i < voxels; i += 11) values[i] = NAN;
  for (size_t i = 8; i < voxels; i += 31) values[i] = i % 2 ? INFINITY : -INFINITY;  // no data, as NaN
  for (size_t i = 7; i < voxels; i += 23) values[i] = 10.0f;
  for (size_t i = 4; i < voxels; i += 29) values[i] = 0.0f;
  std::unique_ptr<FieldHistogramKernel> made;
  try {
    made = std::make_unique<FieldHistogramKernel>(ctx, bins, mode);
  } catch (const std::invalid_argument& e) {
    return check.skip(std::string("needs ") + e.what());
  }
  const FieldHistogramKernel& kernel = *made;
  check.require(kernel.mode() == mode, "the kernel chose another path");
  DeviceField field(ctx, values, "selftest field", chunk_voxels);
  const FieldHistogram g = kernel.run(field, 0.0, 10.0);
  const FieldHistogram c = field_histogram_cpu(values, 0.0, 10.0, bins);
  check.equal("values below", 0, double(g.below), double(c.below));
  check.equal("values above", 0, double(g.above), double(c.above));
  check.equal("NaN values", 0, double(g.nan), double(c.nan));
  check.equal("values counted", 0, double(g.finite() + g.nan), double(voxels));
  for (uint32_t k = 0; k < bins; ++k) check.equal("bin", k, double(g.bins[k]), double(c.bins[k]));
}

// The bench's read bound: the sums of both fields' value bits are integers, equal to the
// reference's exactly (every voxel read once), NaN and infinities among the values; `voxels` 0
// means four of the device's longest segments plus one (quad_segments.glsl); dispatches of
// `range_quads` quads (0: the device's) start inside chunks; lanes of `lane_voxels` (0: the
// device's layout; else the run modes' groups, from one quad per lane to one workgroup whose
// lanes take many segments).
void read_bound(Context& ctx, Check& check, size_t voxels, uint64_t chunk_voxels, uint64_t range_quads,
                uint64_t lane_voxels) {
  if (voxels == 0) voxels = 4 * size_t(ctx.subgroup_size()) * TFM_REDUCE_SEGMENT_STEPS + 1;
  std::vector<float> ref = random_floats(voxels, 17u + uint32_t(voxels), -3.0f, 3.0f);
  std::vector<float> opt = random_floats(voxels, 29u + uint32_t(voxels), 0.0f, 100.0f);
  for (size_t i = 5; i < voxels; i += 13) ref[i] = NAN;
  for (size_t i = 9; i < voxels; i += 31) opt[i] = INFINITY;
  const DeviceField dref(ctx, ref, "selftest ref", chunk_voxels), dopt(ctx, opt, "selftest opt", chunk_voxels);
  const std::array<uint32_t, 2> g = FieldPairReadKernel(ctx, range_quads, lane_voxels).run(dref, dopt);
  const std::array<uint32_t, 2> c = field_pair_bit_sums(ref, opt);
  check.equal("first field's bit sum", 0, double(g[0]), double(c[0]));
  check.equal("second field's bit sum", 1, double(g[1]), double(c[1]));
}

}  // namespace

void add_voxel_cases(CaseList& cases) {
  auto add_assemble = [&](const AssembleCase& c, bool quick) {
    cases.push_back({"assemble_normal_equations", "AssembleNormalEquationsKernel", assemble_name(c), quick,
                     TFM_VOXEL_WORKGROUP, [c](Context& ctx, Check& check) { assemble(ctx, check, c); }});
  };
  const size_t past_group = TFM_VOXEL_WORKGROUP + 1;
  using M = ReductionMode;
  using W = AtomicWidth;
  for (const ReductionOptions& path : reduction_paths()) {
    add_assemble({5003, 64, path.mode, path.atomics, 1024}, true);
    add_assemble({past_group, 3, path.mode, path.atomics}, false);
    add_assemble({8193, 3, path.mode, path.atomics}, false);
    add_assemble({100003, 701, path.mode, path.atomics}, false);
    if (path.mode != M::RunsShared) add_assemble({20000, 701, path.mode, path.atomics}, false);
  }
  // The automatic choice on awkward sizes and TF sizes on both sides of the shared-memory and
  // private-histogram limits (682 and 1024 entries on lavapipe).
  add_assemble({1, 64}, true);
  add_assemble({13, 64}, true);
  add_assemble({past_group, 2}, true);
  add_assemble({8193, 3}, true);
  add_assemble({20000, 700}, false);
  add_assemble({20000, 701}, false);
  // 6N+4 slots of 8 bytes: 192 KiB for N = 4096, beyond every device's shared memory, so the
  // automatic choice is the private or the global path. Not in --quick: on a CPU device its
  // private histograms of 4096 entries take about 140 s to compile with an empty shader cache,
  // most of a cold --quick run (docs/benchmarks.md, "A cold shader cache").
  add_assemble({20000, 4096}, false);
  for (W width : {W::Bits32, W::Bits64}) add_assemble({20000, 4096, M::RunsGlobal, width}, false);
  // 72 KiB of shared slots for N = 1500: run where a device has them, else skipped saying so.
  add_assemble({20000, 1500, M::RunsShared}, true);
  add_assemble({100003, 256}, false);
  // Private histograms in term passes on every device: one pass on a CPU, three within a GPU's
  // smaller private budget (reduction.h).
  add_assemble({100003, 300, M::Private, W::Bits64}, false);
  add_assemble({20000, 2048, M::Private, W::Bits64}, false);
  // The largest private histogram in one pass on a CPU device, over enough voxels for two
  // workgroups (the budget's edge: lavapipe returned wrong sums silently for histograms 3.8x this
  // size once two workgroups ran at once); in passes within a GPU's budget.
  add_assemble({300007, 1024, M::Private, W::Bits64}, false);
  add_assemble({100003, 64, M::Auto, W::Auto, 16384}, false);
  // Chunks split into texel ranges of 64 quads, the last ones short.
  add_assemble({5003, 64, M::Auto, W::Auto, 1027, 64}, true);
  add_assemble({259, 16, M::Auto, W::Auto, 0, 64}, true);

  // The second field stored in each narrower format an embedder may hand over.
  for (FieldFormat format : {FieldFormat::Float16, FieldFormat::Unorm16, FieldFormat::Unorm8})
    for (size_t voxels : {size_t(13), size_t(5003)})
      cases.push_back({"assemble_normal_equations", "AssembleNormalEquationsKernel",
                       voxels_name(voxels) + ", N=64, second field stored as " + field_format_name(format),
                       voxels < 100, TFM_VOXEL_WORKGROUP,
                       [format, voxels](Context& ctx, Check& check) { assemble_stored(ctx, check, format, voxels); }});

  auto add_loss = [&](size_t voxels, uint64_t chunk, bool quick, bool before = false) {
    std::string name = voxels_name(voxels) + (chunk ? ", chunks of " + std::to_string(chunk) : "") +
                       (before ? ", before and after in one pass" : "");
    cases.push_back({"voxel_loss", "VoxelLossKernel", name, quick, TFM_VOXEL_WORKGROUP,
                     [=](Context& ctx, Check& check) { voxel_loss(ctx, check, voxels, chunk, before); }});
  };
  add_loss(1, 0, true);
  add_loss(13, 0, true);
  add_loss(past_group, 0, true);
  add_loss(5000, 1024, true);
  add_loss(13, 0, true, true);
  add_loss(5000, 1024, true, true);
  add_loss(100003, 0, false);
  add_loss(100003, 16384, false);
  add_loss(100003, 16384, false, true);

  auto add_residual = [&](size_t voxels, uint64_t chunk, bool quick) {
    std::string name = voxels_name(voxels) + (chunk ? ", chunks of " + std::to_string(chunk) : "");
    cases.push_back({"residual_map", "ResidualMapKernel", name, quick, TFM_VOXEL_WORKGROUP,
                     [=](Context& ctx, Check& check) { residual(ctx, check, voxels, chunk); }});
  };
  add_residual(1, 0, true);
  add_residual(13, 0, true);
  add_residual(127, 0, true);
  add_residual(TFM_VOXEL_WORKGROUP + 1, 0, true);
  add_residual(70001, 0, false);
  add_residual(5000, 1024, true);
  add_residual(100003, 0, false);
  add_residual(100003, 16384, false);

  using H = HistogramMode;
  auto add_histogram = [&](size_t voxels, uint32_t bins, H mode, uint64_t chunk, bool quick) {
    const char* path = mode == H::Private ? "private" : mode == H::Shared ? "shared" : "global";
    std::string name = voxels_name(voxels) + ", " + std::to_string(bins) + " bins, " + path +
                       (chunk ? ", chunks of " + std::to_string(chunk) : "");
    cases.push_back({"field_histogram", "FieldHistogramKernel", name, quick, TFM_VOXEL_WORKGROUP,
                     [=](Context& ctx, Check& check) { histogram(ctx, check, voxels, bins, mode, chunk); }});
  };
  for (size_t voxels : {size_t(1), size_t(13), past_group, size_t(70001)})
    for (uint32_t bins : {1u, 7u, 100u, 4096u})
      for (H mode : {H::Private, H::Shared, H::Global}) add_histogram(voxels, bins, mode, 0, voxels < 70001);
  add_histogram(1, 16, H::Shared, 0, true);
  add_histogram(13, 7, H::Global, 0, true);
  add_histogram(13, 7, H::Private, 0, true);
  add_histogram(past_group, 4096, H::Shared, 0, true);
  add_histogram(past_group, 4096, H::Private, 0, true);
  add_histogram(5000, 65536, H::Global, 1024, true);
  add_histogram(100003, 4096, H::Shared, 16384, false);
  add_histogram(100003, 4096, H::Private, 16384, false);

  auto add_read = [&](size_t voxels, uint64_t chunk, uint64_t range_quads, bool quick,
                      uint64_t lane = 0) {
    std::string name = voxels ? voxels_name(voxels) : "4 segments + 1 voxel";
    if (chunk) name += ", chunks of " + std::to_string(chunk);
    if (range_quads) name += ", ranges of " + std::to_string(range_quads) + " quads";
    if (lane) name += ", lanes of " + std::to_string(lane) + " voxels";
    cases.push_back({"field_pair_read", "FieldPairReadKernel", name, quick, TFM_VOXEL_WORKGROUP,
                     [=](Context& ctx, Check& check) { read_bound(ctx, check, voxels, chunk, range_quads, lane); }});
  };
  for (size_t voxels : {size_t(1), size_t(3), size_t(4), size_t(5), 4 * past_group - 1, size_t(0), size_t(70001)})
    for (uint64_t chunk : {uint64_t(0), uint64_t(1024)})
      for (uint64_t range_quads : {uint64_t(0), uint64_t(64)}) add_read(voxels, chunk, range_quads, voxels < 70001);
  add_read(4 * past_group + 3, 1024, 0, true);
  for (uint64_t lane : {uint64_t(4), uint64_t(1 << 20)}) {  // one quad per lane; one workgroup
    add_read(0, 0, 0, true, lane);
    add_read(70001, 1024, 64, false, lane);
  }
  add_read(100003, 0, 0, false);
}

}  // namespace tfm::selftest
