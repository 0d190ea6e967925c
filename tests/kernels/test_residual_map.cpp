// Residual-map kernel against a double-precision CPU reference: awkward sizes (1, 13, 127, one
// past a workgroup), NaNs in either field, fields split into several buffers, the same bits for
// every workgroup size and range split, zero for a field compared with itself.
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "commands.h"
#include "gpu_voxel_ops.h"
#include "residual.h"
#include "render_layout.h"
#include "residual_map.h"
#include "shared_layout.h"
#include "test_data.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using test::random_tf;

// T(v) with the shaders' float mapping (bit-identical j and w), interpolated in double.
bool classify(const TransferFunction& tf, const FieldMapping& m, float v, Rgba& out) {
  uint32_t j;
  float w;
  if (!tf_coordinate(v, m, j, w)) return false;
  for (int c = 0; c < 4; ++c) out[c] = std::clamp((1.0 - w) * tf.rgba[j][c] + double(w) * tf.rgba[j + 1][c], 0.0, 1.0);
  return true;
}

std::vector<double> residual_cpu(const std::vector<float>& ref, const std::vector<float>& opt,
                                 const TransferFunction& ref_tf, const TransferFunction& opt_tf,
                                 const FieldMapping& rm, const FieldMapping& om) {
  std::vector<double> out(ref.size(), 0.0);
  for (size_t i = 0; i < ref.size(); ++i) {
    Rgba b, v;
    if (!classify(ref_tf, rm, ref[i], b) || !classify(opt_tf, om, opt[i], v)) continue;
    const double pb[4] = {b[0] * b[3], b[1] * b[3], b[2] * b[3], b[3]};
    const double pv[4] = {v[0] * v[3], v[1] * v[3], v[2] * v[3], v[3]};
    double s = 0;
    for (int c = 0; c < 4; ++c) s += (pb[c] - pv[c]) * (pb[c] - pv[c]);
    out[i] = std::sqrt(s);
  }
  return out;
}

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

class ResidualMap : public test::GpuTest {
 protected:
  void check(size_t n, uint64_t max_chunk_voxels, uint32_t seed) {
    Volume ref, opt;
    random_fields(n, seed, ref, opt);
    const TransferFunction ref_tf = random_tf(23, seed + 1), opt_tf = random_tf(64, seed + 2);
    const FieldMapping rm = make_mapping({0, 1}, 23), om = make_mapping({20, 25}, 64);
    DeviceField ref_dev(ctx(), ref.values, "ref", max_chunk_voxels);
    DeviceField opt_dev(ctx(), opt.values, "opt", max_chunk_voxels);
    Buffer rtf = upload_tf(ctx(), ref_tf, "ref tf"), otf = upload_tf(ctx(), opt_tf, "opt tf");
    const Volume gpu = residual_map_gpu(ctx(), ref, ref_dev, opt_dev, rm, om, rtf, otf);
    const std::vector<double> cpu = residual_cpu(ref.values, opt.values, ref_tf, opt_tf, rm, om);
    ASSERT_EQ(gpu.values.size(), n);
    EXPECT_EQ(gpu.dims, ref.dims);
    // Float interpolation and premultiplication of values in [0,1] (a few roundings of 2^-24
    // each) and a float sqrt of a sum <= 4: errors stay below 1e-6.
    for (size_t i = 0; i < n; ++i) {
      ASSERT_NEAR(gpu.values[i], cpu[i], 1e-6) << "voxel " << i << " of " << n;
      if (std::isnan(ref.values[i]) || std::isnan(opt.values[i])) ASSERT_EQ(gpu.values[i], 0.0f) << "voxel " << i;
    }
  }
};

TEST_F(ResidualMap, MatchesCpuReferenceOnAwkwardSizes) {
  for (size_t n : {size_t(1), size_t(13), size_t(127), size_t(TFM_VOXEL_WORKGROUP + 1), size_t(70001)}) {
    SCOPED_TRACE(n);
    check(n, 0, uint32_t(n));
  }
}

TEST_F(ResidualMap, MatchesCpuReferenceOnASplitField) { check(5000, 1024, 99); }

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
  const std::vector<double> cpu = residual_cpu(ref.values, opt.values, ref_tf, opt_tf, rm, om);
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
  for (float x : r.values) ASSERT_EQ(x, 0.0f);
  Volume w = v;
  w.dims = {7, 13, 5};
  EXPECT_THROW(residual_map(ctx(), v, tf, {0, 1}, w, tf, {0, 1}), std::runtime_error);
}

}  // namespace
}  // namespace tfm
