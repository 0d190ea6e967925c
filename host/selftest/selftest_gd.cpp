// Self-test cases of the gradient-descent kernels: gd_gradient (l2 and l1 loss and gradient sums,
// every reduction mode and atomic width) against a double CPU sum, and gd_update (one Adam and one
// Jacobi-scaled SGD step) against a hand computation.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/gradient_descent.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/selftest/selftest_support.h"

namespace tfm::selftest {
namespace {

struct GradientCase {
  size_t voxels;
  bool l1;
  ReductionOptions path;
  uint64_t chunk_voxels = 0;
};

// Bounds (tests/host/solvers/test_solver_gradient_descent.cpp): the kernel forms e in float, within 1e-6 of
// the double value for values in [0,1]. l2: terms (1-w) e, w e, each a float product (2^-22
// relative with the roundings of w and 1 - w), plus 1e-6 per term for e and 2^-32 per term for
// the fixed-point truncation. l1: a sign can flip only where |e| < 1e-6, moving the sum by at
// most that term's full weight (2). Loss: e^2 (or |e|) within 3e-6 per component plus 2^-32.
void gradient(Context& ctx, Check& check, const GradientCase& c) {
  const uint32_t n = 9;
  const std::string missing = reduction_unavailable(ctx, c.path, n, signed_accumulator_bytes(n));
  if (!missing.empty()) return check.skip(missing);
  const ResidualCaseInputs in(ctx, c.voxels, 61, n, c.chunk_voxels);
  const FieldPair& p = in.pair;
  const std::vector<float>& ref_tf_floats = in.ref_tf_floats;
  const FieldMapping &ref_map = in.ref_map, &opt_map = in.opt_map;
  const std::vector<float> x = random_floats(4 * n, 3, 0.0f, 1.0f);
  Buffer xb = make_buffer<float>(ctx, x, "selftest x");
  Buffer accum(ctx, gd_accumulator_bytes(n), MemoryUsage::Device, "selftest GD accumulators");
  const GdGradientKernel kernel(ctx, n, c.l1, c.path);
  check.require(kernel.mode() == c.path.mode, "the kernel did not take the requested path");
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  // The zeroed accumulators before the kernel adds to them.
  batch.barrier();
  kernel.record(batch, in.ref, in.opt, ref_map, opt_map, in.tf, xb, accum);
  batch.submit_and_wait();
  const std::vector<uint32_t> words = read_words(ctx, accum, gd_accumulator_bytes(n) / 4);
  const size_t loss_word = size_t(TFM_FIXED_SLOT_WORDS) * TFM_GD_LOSS_SLOT(n);
  const std::vector<double> grad = decode_signed_fixed_point(std::vector<uint32_t>(words.begin(), words.begin() + loss_word));
  const std::vector<double> loss = decode_fixed_point(std::vector<uint32_t>(words.begin() + loss_word, words.end()));

  std::vector<double> expected(4 * n, 0.0), bound(4 * n, 1e-12);
  double expected_loss[4] = {0, 0, 0, 0}, loss_bound = double(c.voxels) * std::ldexp(1.0, -32) + 1e-12;
  for (size_t i = 0; i < c.voxels; ++i) {
    uint32_t j;
    float w;
    double b[4];
    if (!classify(ref_tf_floats, ref_map, p.ref[i], b) || !tf_coordinate(p.opt[i], opt_map, j, w)) continue;
    for (int ch = 0; ch < 4; ++ch) {
      const double e = (1.0 - w) * x[4 * j + ch] + double(w) * x[4 * (j + 1) + ch] - b[ch];
      const double d = c.l1 ? (e > 0 ? 1.0 : (e < 0 ? -1.0 : 0.0)) : e;
      const double flip = c.l1 ? (std::abs(e) < 1e-6 ? 2.0 : 0.0) : 1e-6;
      expected[4 * j + ch] += (1.0 - w) * d;
      expected[4 * (j + 1) + ch] += double(w) * d;
      bound[4 * j + ch] += (1.0 - w) * (std::abs(d) * std::ldexp(1.0, -22) + flip) + std::ldexp(1.0, -32);
      bound[4 * (j + 1) + ch] += double(w) * (std::abs(d) * std::ldexp(1.0, -22) + flip) + std::ldexp(1.0, -32);
      expected_loss[ch] += c.l1 ? std::abs(e) : e * e;
      loss_bound += 3e-6;
    }
  }
  for (size_t k = 0; k < expected.size(); ++k) check.near("gradient slot (4j+c)", k, grad[k], expected[k], bound[k]);
  for (int ch = 0; ch < 4; ++ch) check.near("loss, channel", ch, loss[ch], expected_loss[ch], loss_bound);
}

// Signed 32.32 accumulator words of `sums` (two's complement over two words, shaders/fixed_point.glsl;
// exact: every sum is a multiple of 2^-10), followed by the loss slots.
std::vector<uint32_t> encode_signed(const std::vector<double>& sums) {
  std::vector<uint32_t> words(TFM_FIXED_SLOT_WORDS * (sums.size() + 4), 0u);
  for (size_t k = 0; k < sums.size(); ++k) {
    const uint64_t v = uint64_t(std::llround(sums[k] * 4294967296.0));
    words[TFM_FIXED_SLOT_WORDS * k] = uint32_t(v);
    words[TFM_FIXED_SLOT_WORDS * k + 1] = uint32_t(v >> 32);
  }
  return words;
}

// One step from hand-made state. Bounds (tests/host/solvers/test_solver_gradient_descent.cpp): the gradient g
// is a few float operations, within 1e-6 of the magnitudes of its terms (which may cancel); the
// Adam moments within 1e-6 of theirs plus what g carries; x in [0,1] after a float step is within
// a few ulps of the step and of x: 1e-6.
void update(Context& ctx, Check& check, uint32_t n, bool adam) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> sums(4 * n);
  for (double& s : sums) s = std::ldexp(std::round((u(rng) - 0.5) * 4096.0), -10);
  std::vector<float> x(4 * n), m(4 * n), v(4 * n), inv_diag(n);
  for (auto& e : x) e = float(u(rng));
  for (auto& e : m) e = float((u(rng) - 0.5) * 1e-3);
  for (auto& e : v) e = float(u(rng) * 1e-6);
  for (auto& e : inv_diag) e = float(1.0 / (1.0 + 100.0 * u(rng)));
  Buffer accum = make_buffer<uint32_t>(ctx, encode_signed(sums), "selftest GD accumulators");
  Buffer xb = make_buffer<float>(ctx, x, "selftest x"), mb = make_buffer<float>(ctx, m, "selftest Adam m");
  Buffer vb = make_buffer<float>(ctx, v, "selftest Adam v"), db = make_buffer<float>(ctx, inv_diag, "selftest inv diag");
  Buffer gb(ctx, uint64_t(n) * 16, MemoryUsage::Device, "selftest gradient");
  gpu::GdUpdatePush push{};
  push.tf_size = n;
  push.optimizer = adam ? TFM_GD_OPTIMIZER_ADAM : TFM_GD_OPTIMIZER_SGD;
  push.data_scale = 1e-4f;
  push.reg_scale = 2e-4f;
  push.ridge_weight = 3.0f;
  push.smooth_weight = 5.0f;
  push.lr = 0.01f;
  push.beta1 = 0.9f;
  push.beta2 = 0.999f;
  push.bias1 = float(1.0 / (1.0 - std::pow(0.9, 3.0)));  // step t = 3
  push.bias2 = float(1.0 / (1.0 - std::pow(0.999, 3.0)));
  push.epsilon = 1e-8f;
  const GdUpdateKernel kernel(ctx);
  CommandBatch batch(ctx);
  kernel.record(batch, push, {&accum, &xb, &mb, &vb, &db, &gb});
  batch.submit_and_wait();
  std::vector<float> x2(4 * n), m2(4 * n), v2(4 * n), g2(4 * n);
  readback(ctx, xb, x2.data(), x2.size() * 4);
  readback(ctx, mb, m2.data(), m2.size() * 4);
  readback(ctx, vb, v2.data(), v2.size() * 4);
  readback(ctx, gb, g2.data(), g2.size() * 4);
  // The kernel's constants are the floats of the push block: the hand computation uses them too.
  const double b1 = push.beta1, b2 = push.beta2, lr = push.lr;
  for (uint32_t j = 0; j < n; ++j)
    for (int ch = 0; ch < 4; ++ch) {
      const size_t k = 4 * j + ch;
      double dtd = 0.0;
      if (j > 0) dtd += double(x[k]) - x[k - 4];
      if (j + 1 < n) dtd += double(x[k]) - x[k + 4];
      const double g = 1e-4 * sums[k] + 2e-4 * (3.0 * x[k] + 5.0 * dtd);
      const double g_bound = 1e-6 * (1e-4 * std::abs(sums[k]) + 2e-4 * (3.0 + 5.0 * 2.0)) + 1e-12;
      check.near("gradient (4j+c)", k, g2[k], g, g_bound);
      double step;
      if (adam) {
        const double mk = b1 * m[k] + (1.0 - b1) * g, vk = b2 * v[k] + (1.0 - b2) * g * g;
        check.near("Adam m (4j+c)", k, m2[k], mk, 1e-6 * (b1 * std::abs(m[k]) + (1.0 - b1) * std::abs(g)) + g_bound);
        check.near("Adam v (4j+c)", k, v2[k], vk, 1e-6 * vk + 0.002 * std::abs(g) * g_bound + 1e-20);
        step = lr * (mk * double(push.bias1)) / (std::sqrt(vk * double(push.bias2)) + double(push.epsilon));
      } else {
        step = lr * g * inv_diag[j] / double(push.reg_scale);
      }
      check.near("x (4j+c)", k, x2[k], std::clamp(x[k] - step, 0.0, 1.0), 1e-6);
    }
}

}  // namespace

void add_gd_cases(CaseList& cases) {
  const size_t past_group = TFM_VOXEL_WORKGROUP + 1;
  for (bool l1 : {false, true})
    for (const ReductionOptions& path : reduction_paths()) {
      const std::string suffix = std::string(l1 ? ", l1" : ", l2") + reduction_name(path);
      auto add = [&](GradientCase c, bool quick) {
        c.l1 = l1;
        c.path = path;
        std::string name = voxels_name(c.voxels) + suffix;
        if (c.chunk_voxels) name += ", chunks of " + std::to_string(c.chunk_voxels);
        cases.push_back({"gd_gradient", "GdGradientKernel", name, quick, TFM_VOXEL_WORKGROUP,
                         [c](Context& ctx, Check& check) { gradient(ctx, check, c); }});
      };
      add({13, l1, path}, false);
      add({past_group, l1, path}, false);
      add({5000, l1, path, 1024}, true);
      add({100003, l1, path}, false);
      add({100003, l1, path, 16384}, false);
    }
  // One workgroup asked for 400 003 voxels: its lanes would walk 12 500 quads each at 6 loop
  // iterations a quad, past lavapipe's 65535 (kernels/reduction.h); the count is raised instead.
  for (bool l1 : {false, true}) {
    const ReductionOptions one_group{ReductionMode::Private, AtomicWidth::Bits64, 1};
    const GradientCase c{400003, l1, one_group};
    cases.push_back({"gd_gradient", "GdGradientKernel",
                     voxels_name(c.voxels) + (l1 ? ", l1" : ", l2") + reduction_name(one_group), false,
                     TFM_VOXEL_WORKGROUP, [c](Context& ctx, Check& check) { gradient(ctx, check, c); }});
  }
  for (bool adam : {true, false}) {
    auto add = [&](uint32_t n, bool quick) {
      const std::string name = "N=" + std::to_string(n) + (adam ? ", Adam step" : ", SGD step (Jacobi-scaled)");
      cases.push_back({"gd_update", "GdUpdateKernel", name, quick, TFM_VECTOR_WORKGROUP,
                       [n, adam](Context& ctx, Check& check) { update(ctx, check, n, adam); }});
    };
    add(2, true);
    add(TFM_VECTOR_WORKGROUP + 44, true);  // more entries than invocations: two blocks
    add(4096, false);
  }
}

}  // namespace tfm::selftest
