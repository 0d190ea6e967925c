// The self-test's comparison record and shared test data.
#include "tfmatch/selftest/selftest_support.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>

#include "tfmatch/kernels/gpu_voxel_ops.h"  // upload_tf
#include "tfmatch/reference/residual_map_cpu.h"
#include "tfmatch/shaders/correlation_layout.h"

namespace tfm::selftest {

void Check::near(const char* what, uint64_t index, double device, double reference, double bound) {
  if (!perturbed_) {
    device += perturbation_;
    perturbed_ = true;
  }
  ++compared_;
  double error = std::abs(device - reference);
  if (std::isnan(error)) error = std::numeric_limits<double>::infinity();
  const bool ok = error <= bound;
  // Ratio to the bound; an exact comparison (bound 0) is at ratio 0 when equal, infinite when not.
  const double ratio = bound > 0.0 ? error / bound : (error == 0.0 ? 0.0 : std::numeric_limits<double>::infinity());
  if (ratio > worst_ratio_) {
    worst_ratio_ = ratio;
    worst_error_ = error;
    worst_bound_ = bound;
  }
  if (!ok && failure_.empty()) {
    std::ostringstream os;
    os.precision(9);
    os << what << " " << index << ": device " << device << ", reference " << reference << " (bound " << bound << ")";
    failure_ = os.str();
  }
}

void Check::require(bool ok, const std::string& message) {
  if (!ok && failure_.empty()) failure_ = "case precondition: " + message;
}

FieldPair random_pair(size_t voxels, uint32_t seed, const FieldRange& opt_range, uint32_t opt_tf_size) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  const float lo = float(opt_range.lo), width = float(opt_range.hi - opt_range.lo);
  FieldPair p{std::vector<float>(voxels), std::vector<float>(voxels)};
  for (size_t i = 0; i < voxels; ++i) {
    p.ref[i] = u(rng);
    p.opt[i] = lo + width * u(rng);
    if (i % 7 == 3) p.opt[i] = lo + width * float(rng() % opt_tf_size) / float(opt_tf_size - 1);  // on a node
    if (i % 11 == 5) p.ref[i] = NAN;
    if (i % 13 == 6) p.opt[i] = NAN;
    if (i % 17 == 8) p.opt[i] = i % 34 == 8 ? INFINITY : -INFINITY;  // no data too (no_data())
    if (i % 19 == 2) p.ref[i] = INFINITY;
  }
  return p;
}

ResidualCaseInputs::ResidualCaseInputs(Context& ctx, size_t voxels, uint32_t seed, uint32_t n, uint64_t chunk_voxels)
    : pair(random_pair(voxels, seed + uint32_t(voxels), {0.0, 1.0}, n)),
      ref_tf(random_tf(11, seed + 1, -0.1, 1.1)),
      ref_tf_floats(ref_tf.as_floats()),
      ref_map(make_mapping({0.0, 1.0}, 11)),
      opt_map(make_mapping({0.0, 1.0}, n)),
      ref(ctx, pair.ref, "selftest reference", chunk_voxels),
      opt(ctx, pair.opt, "selftest field", chunk_voxels),
      tf(upload_tf(ctx, ref_tf, "selftest reference TF")) {}

TransferFunction random_tf(uint32_t n, uint32_t seed, double lo, double hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  TransferFunction tf;
  tf.rgba.resize(n);
  for (auto& e : tf.rgba) e = {u(rng), u(rng), u(rng), u(rng)};
  return tf;
}

std::vector<float> random_floats(size_t count, uint32_t seed, float lo, float hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, hi);
  std::vector<float> v(count);
  for (float& x : v) x = u(rng);
  return v;
}

CorrelationEnsemble correlation_test_ensemble(uint32_t members, uint64_t voxels, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> grid(0, 4096);
  auto quantized = [](double v, double step) { return float(std::clamp(std::round(v / step) * step, 0.0, 4.0)); };
  CorrelationEnsemble e{members, voxels, std::vector<float>(size_t(members) * voxels)};
  std::vector<double> x(members);
  for (double& v : x) v = grid(rng) / 1024.0;
  for (uint64_t v = 0; v < voxels; ++v) {
    const double strength = std::cos(0.7 * double(v));
    const double step = v % 3 == 2 ? 0.25 : 1.0 / 1024;
    for (uint32_t m = 0; m < members; ++m) {
      const double noise = grid(rng) / 1024.0, xm = strength >= 0 ? x[m] : 4.0 - x[m];
      double y = std::abs(strength) * xm + (1 - std::abs(strength)) * noise;
      if (m < 2) y = (m == 0) == (strength >= 0) ? 0.0 : 4.0;  // the series spans [0, 4]
      e.values[m * voxels + v] = v == 0 ? float(m < 2 ? 4.0 * m : x[m]) : quantized(y, step);
    }
    if (v == 5) e.values[(members / 2) * voxels + v] = NAN;
    if (v == 7)
      for (uint32_t m = 0; m < members; ++m) e.values[m * voxels + v] = 1.5f;
  }
  return e;
}

CorrelationEnsemble bin_edge_ensemble(uint32_t members, uint64_t voxels) {
  CorrelationEnsemble e{members, voxels, std::vector<float>(size_t(members) * voxels)};
  for (uint32_t m = 0; m < members; ++m)
    for (uint64_t v = 0; v < voxels; ++v) {
      // Members 0 and 1 hold 0 and 3, so every range is exactly 3.
      const uint32_t k = m == 0 ? 0u : m == 1 ? 10u : uint32_t((m * 7 + v * 3 + m * v) % 11);
      float value = float(k * 3) / 10.0f;
      const int ulps = m < 2 ? 0 : int((m + 5 * v) % 9) - 4;
      for (int u = 0; u < std::abs(ulps); ++u) value = std::nextafter(value, ulps < 0 ? 0.0f : 4.0f);
      e.values[m * voxels + v] = std::clamp(value, 0.0f, 3.0f);
    }
  return e;
}

CorrelationEnsemble pearson_shift_ensemble(uint32_t members, float offset, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  // How far from the mean a of the other members member 0 must lie for the ratio q: with
  // y0 = a + t, M (mean - y0)^2 = t^2 (M - 1)^2 / M and syy = ss + t^2 (M - 1) / M.
  const double n = members;
  auto distance = [n](const std::vector<double>& s, double q) {
    const double a = std::accumulate(s.begin() + 1, s.end(), 0.0) / (n - 1);
    double ss = 0;
    for (size_t m = 1; m < s.size(); ++m) ss += (s[m] - a) * (s[m] - a);
    return std::pair{a, std::sqrt(q * ss * n / ((n - 1) * (n - 1 - q)))};
  };
  std::vector<double> x(members);
  for (double& v : x) v = normal(rng);
  const auto [x_mean, x_distance] = distance(x, 0.9 * (n - 1));
  x[0] = x_mean + x_distance;
  const double limit = TFM_CORR_PEARSON_SHIFT_LIMIT;
  std::vector<double> ratios;
  for (double q : {0.0, 0.5, 1.0, 2.0, 4.0, 8.0, limit - 1, limit - 0.1, limit + 0.1, limit + 1, 2 * limit, 100.0,
                   1000.0})
    if (q < n - 1) ratios.push_back(q);
  for (double f : {0.5, 0.9, 0.99, 0.999}) ratios.push_back(f * (n - 1));
  // Voxel 0 holds the reference; then each ratio with member 0 above the others, then below.
  CorrelationEnsemble e{members, 1 + 2 * ratios.size(), {}};
  e.values.resize(size_t(members) * e.voxels);
  for (uint32_t m = 0; m < members; ++m) e.values[m * e.voxels] = float(offset + x[m]);
  std::vector<double> y(members);
  for (uint64_t v = 1; v < e.voxels; ++v) {
    for (uint32_t m = 1; m < members; ++m) y[m] = 0.8 * x[m] + 0.6 * normal(rng);
    const auto [mean, t] = distance(y, ratios[(v - 1) / 2]);
    y[0] = v % 2 ? mean + t : mean - t;
    for (uint32_t m = 0; m < members; ++m) e.values[m * e.voxels + v] = float(offset + y[m]);
  }
  return e;
}

CorrelationEnsemble spread_ensemble(uint32_t members, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> grid(0, 4096), wide(0, 16000);
  CorrelationEnsemble e{members, 4, std::vector<float>(size_t(members) * 4)};
  for (uint32_t m = 0; m < members; ++m) {
    const int x = m < 2 ? 4096 * int(m) : grid(rng);
    e.values[m * 4 + 0] = float(x) / 1024.0f;
    e.values[m * 4 + 1] = float(wide(rng)) / 4.0f;
    e.values[m * 4 + 2] = float(x) * (1000.0f / 1024.0f);  // 125 x / 128: exact
    e.values[m * 4 + 3] = float(grid(rng)) / (1024.0f * 1024.0f);
  }
  return e;
}

bool classify(const std::vector<float>& tf, const FieldMapping& map, float v, double out[4]) {
  return tf_colour_cpu(tf, map, v, out);
}

std::vector<uint32_t> read_words(Context& ctx, const Buffer& buffer, size_t words) {
  std::vector<uint32_t> out(words);
  readback(ctx, buffer, out.data(), words * sizeof(uint32_t));
  return out;
}

bool fits_shared_memory(const Context& ctx, uint64_t bytes) {
  return bytes <= ctx.limits().maxComputeSharedMemorySize;
}

std::vector<ReductionOptions> reduction_paths() {
  std::vector<ReductionOptions> paths;
  for (ReductionMode mode : {ReductionMode::RunsShared, ReductionMode::RunsGlobal, ReductionMode::Private})
    for (AtomicWidth width : {AtomicWidth::Bits32, AtomicWidth::Bits64})
      if (mode != ReductionMode::Private || width == AtomicWidth::Bits64) paths.push_back({mode, width});
  return paths;
}

std::string reduction_name(const ReductionOptions& o) {
  std::string s;
  if (o.mode != ReductionMode::Auto) s += std::string(", ") + reduction_mode_name(o.mode);
  if (o.atomics != AtomicWidth::Auto) s += o.atomics == AtomicWidth::Bits64 ? ", 64-bit atomics" : ", 32-bit atomics";
  if (o.workgroups) s += ", " + std::to_string(o.workgroups) + (o.workgroups == 1 ? " workgroup asked" : " workgroups asked");
  return s;
}

std::string reduction_unavailable(const Context& ctx, const ReductionOptions& o, uint32_t tf_size,
                                  uint64_t shared_bytes, uint32_t private_max_bins) {
  if ((o.atomics == AtomicWidth::Bits64 || o.mode == ReductionMode::Private) && !ctx.int64_atomics())
    return "needs shaderInt64 with 64-bit buffer and shared atomics";
  if (o.mode == ReductionMode::RunsShared && !fits_shared_memory(ctx, shared_bytes))
    return needs_shared_memory(ctx, shared_bytes);
  if (o.mode == ReductionMode::Private && tf_size > private_limit(ctx, private_max_bins))
    return "private histograms hold at most " + std::to_string(private_limit(ctx, private_max_bins)) +
           " TF entries on this device";
  return "";
}

std::string needs_shared_memory(const Context& ctx, uint64_t bytes) {
  std::ostringstream os;
  os.precision(3);
  os << "needs " << double(bytes) / 1024.0 << " KiB of workgroup shared memory (maxComputeSharedMemorySize "
     << double(ctx.limits().maxComputeSharedMemorySize) / 1024.0 << " KiB)";
  return os.str();
}

std::string voxels_name(size_t voxels) { return std::to_string(voxels) + (voxels == 1 ? " voxel" : " voxels"); }

}  // namespace tfm::selftest
