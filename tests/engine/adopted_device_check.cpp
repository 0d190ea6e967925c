// The kernel run shared by the embedding hosts (tests/engine/).
#include "adopted_device_check.h"

#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include <gtest/gtest.h>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/reference/normal_equations_cpu.h"

namespace tfm::test {

void expect_adopted_device_computes(const ExternalDevice& external) {
  // 777 voxels: not a multiple of any workgroup size.
  std::vector<float> ref(777), opt(777);
  for (size_t i = 0; i < ref.size(); ++i) ref[i] = float(i % 50) / 49.0f, opt[i] = float((i * 7) % 31) / 30.0f;
  TransferFunction tf;
  tf.rgba = {{0, 0.2, 0.4, 0.0}, {1, 0.5, 0.1, 0.7}, {0.3, 0.9, 0.6, 1.0}};
  const uint32_t n = 8;
  FieldMapping rm = make_mapping({0, 1}, 3), om = make_mapping({0, 1}, n);
  NormalEquations cpu = assemble_normal_equations_cpu(ref, opt, rm, om, tf);

  auto ctx = Context::adopt(external);
  EXPECT_FALSE(ctx->owns_device());
  EXPECT_EQ(ctx->device(), external.device);

  std::vector<uint32_t> words(1027), back(1027, 0);
  std::iota(words.begin(), words.end(), 7u);
  Buffer b(*ctx, words.size() * 4, MemoryUsage::Device, "round trip");
  upload(*ctx, b, words.data(), words.size() * 4);
  readback(*ctx, b, back.data(), back.size() * 4);
  EXPECT_EQ(words, back);

  DeviceField r(*ctx, ref, "ref"), o(*ctx, opt, "opt");
  Buffer tfb = upload_tf(*ctx, tf, "tf");
  GpuNormalEquations gpu(*ctx, n);
  gpu.add(r, o, rm, om, tfb);
  NormalEquations g = gpu.result();
  ASSERT_EQ(g.voxels, cpu.voxels);
  // As in test_assembly.cpp: every term is non-negative, so float rounding is within 1e-6
  // relative, and 32.32 fixed-point truncation adds under 2^-32 per voxel.
  const double abs_tol = double(ref.size()) * std::ldexp(1.0, -32);
  auto expect_close = [&](double gpu_value, double cpu_value, const char* what, uint32_t j) {
    EXPECT_LE(std::abs(gpu_value - cpu_value), 1e-6 * std::abs(cpu_value) + abs_tol)
        << what << "[" << j << "]: gpu " << gpu_value << " cpu " << cpu_value;
  };
  for (uint32_t j = 0; j < n; ++j) {
    expect_close(g.diag[j], cpu.diag[j], "diag", j);
    if (j + 1 < n) expect_close(g.off[j], cpu.off[j], "off", j);
    for (int c = 0; c < 4; ++c) expect_close(g.rhs(j, c), cpu.rhs(j, c), "rhs", j * 4 + c);
  }
}

}  // namespace tfm::test
