// ±Inf is "no data" as NaN is (docs/design.md, no_data() in shaders/tf_common.glsl and
// host/model/field_mapping.h): every voxel kernel and its CPU reference give the same bits for a
// field whose no-data voxels hold +Inf or -Inf as for the same field with NaN there. Before,
// infinities were clamped to the TF's ends by the voxel kernels, while the ranges skipped them,
// and a trilinear sample beside one was Inf * 0 = NaN, which the renderer classified as TF
// entry 0 instead of leaving it empty.
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "test_data.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/histogram.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/residual_map.h"
#include "tfmatch/kernels/visibility_weights.h"
#include "tfmatch/model/cameras.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "tfmatch/reference/histogram_cpu.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/reference/residual_map_cpu.h"
#include "tfmatch/reference/visibility_weights_cpu.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using NoData = test::GpuTest;

constexpr std::array<uint64_t, 3> kDims{13, 9, 7};

// A smooth field with holes: NaN where `hole` is, or alternately +Inf and -Inf there.
Volume holed_field(uint32_t seed, bool infinite) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  uint64_t holes = 0;
  return test::make_volume(kDims, {1, 1, 1}, "holed", [&](uint64_t x, uint64_t y, uint64_t z, uint64_t) {
    const float v = 0.5f + 0.4f * float(std::sin(0.7 * double(x) + 0.3 * double(y)) * std::cos(0.5 * double(z))) +
                    0.1f * u(rng);
    const bool hole = (x + 2 * y + 3 * z + seed) % 11 == 0 || (z == 3 && x < 4);
    if (!hole) return v;
    return !infinite ? float(NAN) : (holes++ % 2 ? float(INFINITY) : -float(INFINITY));
  });
}

std::vector<uint32_t> bits_of(const std::vector<float>& v) {
  std::vector<uint32_t> b(v.size());
  std::memcpy(b.data(), v.data(), v.size() * sizeof(float));
  return b;
}

std::vector<float> read_field(Context& ctx, const DeviceField& f) {
  std::vector<float> v(f.voxel_count());
  for (size_t c = 0; c < f.chunk_count(); ++c)
    readback(ctx, f.chunk(c), v.data() + f.chunk_begin(c), f.chunk_size(c) * sizeof(float));
  return v;
}

TEST_F(NoData, InfinitiesAreNoDataInTheVoxelKernelsAsNaNIs) {
  const Volume ref_nan = holed_field(1, false), ref_inf = holed_field(1, true);
  const Volume opt_nan = holed_field(2, false), opt_inf = holed_field(2, true);
  const TransferFunction ref_tf = test::random_tf(9, 3), opt_tf = test::random_tf(12, 4);
  const FieldMapping rm = make_mapping({0, 1}, 9), om = make_mapping({0, 1}, 12);
  const Buffer rtf = upload_tf(ctx(), ref_tf, "ref tf"), otf = upload_tf(ctx(), opt_tf, "opt tf");
  struct Results {
    std::vector<uint64_t> slots, cpu_slots;
    uint64_t voxels;
    std::array<double, 4> loss;
    std::vector<uint32_t> residual;
    FieldHistogram histogram, cpu_histogram;
  };
  const auto run = [&](const Volume& ref, const Volume& opt) {
    Results r;
    const DeviceField dr(ctx(), ref.values, "ref", 320), dopt(ctx(), opt.values, "opt", 320);
    GpuNormalEquations eq(ctx(), 12);
    eq.add(dr, dopt, rm, om, rtf);
    r.slots = eq.fixed_point_slots();
    r.voxels = eq.result().voxels;
    r.cpu_slots = assemble_normal_equations_fixed_point(ref.values, opt.values, rm, om, ref_tf);
    r.loss = voxel_loss_gpu(ctx(), dr, dopt, rm, om, rtf, otf).squared;
    DeviceField out(ctx(), ref.values.size(), "residual", dr.chunk_voxels());
    const ResidualMapKernel kernel(ctx());
    CommandBatch batch(ctx());
    kernel.record(batch, dr, dopt, rm, om, rtf, otf, out);
    batch.submit_and_wait();
    r.residual = bits_of(read_field(ctx(), out));
    r.histogram = FieldHistogramKernel(ctx(), 16).run(dopt, 0.0, 1.0);
    r.cpu_histogram = field_histogram_cpu(opt.values, 0.0, 1.0, 16);
    return r;
  };
  const Results nan = run(ref_nan, opt_nan), inf = run(ref_inf, opt_inf);
  EXPECT_EQ(inf.slots, nan.slots) << "assembly";
  EXPECT_EQ(inf.cpu_slots, nan.cpu_slots) << "assembly's exact CPU emulation";
  EXPECT_EQ(nan.slots, nan.cpu_slots);
  EXPECT_LT(nan.voxels, ref_nan.values.size() * 9 / 10) << "the holes must be no data in the test itself";
  EXPECT_EQ(inf.voxels, nan.voxels);
  EXPECT_EQ(inf.loss, nan.loss) << "voxel loss";
  EXPECT_EQ(inf.residual, nan.residual) << "residual map";
  EXPECT_EQ(inf.histogram.nan, nan.histogram.nan);
  EXPECT_EQ(inf.histogram.bins, nan.histogram.bins);
  EXPECT_EQ(inf.histogram.below + inf.histogram.above, nan.histogram.below + nan.histogram.above);
  EXPECT_EQ(inf.cpu_histogram.nan, inf.histogram.nan);
  EXPECT_EQ(inf.cpu_histogram.above, inf.histogram.above);
  // The CPU references that renders and solvers are checked against.
  std::vector<double> r_nan = residual_map_cpu(ref_nan.values, opt_nan.values, ref_tf.as_floats(), rm,
                                               opt_tf.as_floats(), om),
                      r_inf = residual_map_cpu(ref_inf.values, opt_inf.values, ref_tf.as_floats(), rm,
                                               opt_tf.as_floats(), om);
  EXPECT_EQ(r_inf, r_nan) << "residual_map_cpu";
}

TEST_F(NoData, InfinitiesAreEmptySamplesInRendersAndVisibility) {
  const Volume nan = holed_field(5, false), inf = holed_field(5, true);
  const TransferFunction tf = test::random_tf(8, 6, 0.0, 1.0, 0.2, 1.0);
  RenderSettings s;
  s.width = 37;
  s.height = 29;
  s.step_voxels = 0.41;
  s.opacity_scale = 9.0;
  const RenderedImage g_nan = render_volume(ctx(), nan, tf, {0, 1}, s);
  const RenderedImage g_inf = render_volume(ctx(), inf, tf, {0, 1}, s);
  EXPECT_EQ(bits_of(g_inf.rgba), bits_of(g_nan.rgba)) << "GPU renderer";
  const CpuRender c_nan = render_cpu(nan, tf, {0, 1}, s), c_inf = render_cpu(inf, tf, {0, 1}, s);
  EXPECT_EQ(c_inf.rgba, c_nan.rgba) << "CPU renderer";
  const std::vector<OrbitCamera> cameras = fibonacci_cameras(3, s.camera);
  const FieldMapping map = make_mapping({0, 1}, uint32_t(tf.size()));
  const Buffer tf_buffer = upload_tf(ctx(), tf, "tf");
  const VolumeGeometry geo = VolumeGeometry::from(nan.dims, nan.spacing, s.z_scale);
  const auto weights = [&](const Volume& v) {
    const DeviceField f(ctx(), v.values, "field");
    VisibilityWeightsKernel kernel(ctx(), 1);
    return bits_of(read_field(ctx(), kernel.compute(f, geo, map, tf_buffer, s, cameras).weights));
  };
  EXPECT_EQ(weights(inf), weights(nan)) << "visibility weights";
  EXPECT_EQ(visibility_weights_cpu(inf, tf, {0, 1}, s, cameras, false).weights,
            visibility_weights_cpu(nan, tf, {0, 1}, s, cameras, false).weights)
      << "CPU visibility weights";
}

}  // namespace
}  // namespace tfm
