// Residual-map kernel beyond its case table (host/selftest/selftest_voxel.cpp, run by
// test_kernel_cases.cpp: awkward sizes, NaNs in either field, split fields, against
// residual_map_cpu): the same bits for every workgroup size, range split and chunking, zero for a
// field compared with itself.
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "test_data.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/kernels/residual_map.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/reference/residual_map_cpu.h"
#include "tfmatch/shaders/render_layout.h"
#include "tfmatch/shaders/shared_layout.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using test::random_tf;

// Values in and beside the ranges ([0, 1] and [20, 25]: outside ones are clamped), NaN (no
// data) at every 11th reference and 7th second-field voxel.
void random_fields(size_t n, uint32_t seed, Volume& ref, Volume& opt) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.2f, 1.2f);
  ref.dims = opt.dims = {n, 1, 1};
  for (size_t i = 0; i < n; ++i) {
    ref.values.push_back(i % 11 == 4 ? NAN : u(rng));
    opt.values.push_back(i % 7 == 2 ? NAN : 20.0f + 5.0f * u(rng));
  }
}

using ResidualMap = test::GpuTest;

// Each voxel's residual depends on that voxel alone: every workgroup size, range split and
// chunking writes the same bits (lanes on quads, the count % 4 tail by invocation 0).
TEST_F(ResidualMap, SameBitsForEveryWorkgroupSizeRangeSplitAndChunking) {
  const size_t n = 20011;  // 20011 % 4 = 3: a tail of single voxels
  Volume ref, opt;
  random_fields(n, 77, ref, opt);
  const TransferFunction ref_tf = random_tf(9, 78), opt_tf = random_tf(n % 50 + 2, 79);
  const FieldMapping rm = make_mapping({0, 1}, 9), om = make_mapping({20, 25}, uint32_t(opt_tf.size()));
  Buffer rtf = upload_tf(ctx(), ref_tf, "ref tf"), otf = upload_tf(ctx(), opt_tf, "opt tf");
  auto map = [&](uint64_t chunk_voxels, uint64_t range_quads, uint32_t workgroup) {
    const DeviceField r(ctx(), ref.values, "ref", chunk_voxels), o(ctx(), opt.values, "opt", chunk_voxels);
    DeviceField out(ctx(), n, "residual", r.chunk_voxels());
    const ResidualMapKernel kernel(ctx(), range_quads, workgroup);
    CommandBatch batch(ctx());
    kernel.record(batch, r, o, rm, om, rtf, otf, out);
    batch.submit_and_wait();
    std::vector<uint32_t> bits(n);
    for (size_t c = 0; c < out.chunk_count(); ++c)
      readback(ctx(), out.chunk(c), bits.data() + out.chunk_begin(c), out.chunk_size(c) * sizeof(float));
    return bits;
  };
  const std::vector<uint32_t> whole = map(0, 0, 0);
  for (uint32_t workgroup : {ctx().subgroup_size(), 2 * ctx().subgroup_size(), uint32_t(TFM_VOXEL_WORKGROUP)})
    for (uint64_t range_quads : {uint64_t(0), uint64_t(64), uint64_t(704)})
      for (uint64_t chunk_voxels : {uint64_t(0), uint64_t(4096), uint64_t(1030)}) {
        SCOPED_TRACE("workgroup " + std::to_string(workgroup) + ", ranges of " + std::to_string(range_quads) +
                     " quads, chunks of " + std::to_string(chunk_voxels));
        EXPECT_EQ(map(chunk_voxels, range_quads, workgroup), whole);
      }
  EXPECT_THROW(ResidualMapKernel(ctx(), 100, 0), std::invalid_argument);  // not a multiple of 64
  EXPECT_THROW(ResidualMapKernel(ctx(), 0, ctx().subgroup_size() + 1), std::invalid_argument);
  // And the words are the CPU reference's values.
  const std::vector<double> cpu =
      residual_map_cpu(ref.values, opt.values, ref_tf.as_floats(), rm, opt_tf.as_floats(), om);
  for (size_t i = 0; i < n; ++i) {
    float g;
    std::memcpy(&g, &whole[i], sizeof g);
    ASSERT_NEAR(g, cpu[i], 1e-6) << "voxel " << i;
  }
}

TEST_F(ResidualMap, FieldAgainstItselfIsZeroAndGridMismatchThrows) {
  Volume v;
  v.dims = {13, 7, 5};
  for (size_t i = 0; i < v.voxel_count(); ++i) v.values.push_back(float(i % 29) / 28.0f);
  const TransferFunction tf = random_tf(16, 5);
  const Volume r = residual_map(ctx(), v, tf, {0, 1}, v, tf, {0, 1});
  ASSERT_EQ(r.values.size(), v.voxel_count());
  for (float x : r.values) ASSERT_EQ(x, 0.0f);
  Volume w = v;
  w.dims = {7, 13, 5};
  EXPECT_THROW(residual_map(ctx(), v, tf, {0, 1}, w, tf, {0, 1}), std::runtime_error);
  // The display range: the maximum over the maps shown together, but never below one 8-bit
  // step (float rounding between identical fields is no structure), [0, 1] for all zeros.
  Volume noise = r, larger = r;
  noise.values[3] = 2e-7f;
  larger.values[5] = 0.5f;
  EXPECT_EQ(residual_display_range({&noise}).hi, kResidualDisplayFloor);
  EXPECT_EQ(residual_display_range({&noise, &larger}).hi, 0.5);
  EXPECT_EQ(residual_display_range({&r}).hi, 1.0);
}

// Where device buffers are host memory, the fields on the device (none where the device reads
// them in place), the map and the map read back are checked as one sum: a budget with room for
// all but one of those volumes is refused before anything is made (each part fitted alone, and a
// run went 18-30 % over); with room for them all, the map is made.
TEST_F(ResidualMap, DeviceBuffersAndTheReadBackAreCheckedTogether) {
  if (!device_memory_is_host(ctx())) GTEST_SKIP() << "device memory is not the host's here";
  Volume v;
  v.dims = {256, 256, 64};  // 16 MiB a volume
  v.values.assign(v.voxel_count(), 0.5f);
  const TransferFunction tf = random_tf(16, 5);
  // In place: the map on the device and read back (2 volumes); copied: both fields too (4).
  const uint64_t volumes = DeviceField::reads_host_memory(ctx()) ? 2 : 4;
  set_memory_budget(resident_memory() + (volumes * 16 - 8) * (uint64_t(1) << 20), "--max-memory test");
  try {
    residual_map(ctx(), v, tf, {0, 1}, v, tf, {0, 1});
    ADD_FAILURE() << volumes << " volumes of 16 MiB passed a budget with 8 MiB less left";
  } catch (const MemoryBudgetExceeded& e) {
    EXPECT_NE(std::string(e.what()).find("needs " + std::to_string(volumes * 16) + ".0 MiB"), std::string::npos)
        << e.what();
  }
  set_memory_budget(resident_memory() + (volumes * 16 + 16) * (uint64_t(1) << 20), "--max-memory test");
  EXPECT_NO_THROW(residual_map(ctx(), v, tf, {0, 1}, v, tf, {0, 1}));
  set_memory_budget(0, "");
}

}  // namespace
}  // namespace tfm
