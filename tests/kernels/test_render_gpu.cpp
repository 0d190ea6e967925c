// GPU renderer beyond its case table (host/selftest/selftest_render.cpp, run by
// test_kernel_cases.cpp: awkward grids and images, anisotropic spacing, seven cameras including
// both poles, NaNs, fields in several chunks, early termination and the inverse-march check, each
// against the double-precision CPU renderer): a field of NaN only is transparent and its rays
// still march; rays longer than llvmpipe lets one invocation loop are marched whole in several
// dispatches, and where a kernel cannot split them (DiffDVR, visibility weights) refused.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli_runner.h"
#include "test_data.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/diffdvr.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using RenderGpu = test::GpuTest;

TEST_F(RenderGpu, FullyNaNFieldIsTransparent) {
  const Volume vol = test::make_volume({6, 6, 6}, {1, 1, 1}, "NaN volume",
                                       [](uint64_t, uint64_t, uint64_t, uint64_t) { return float(NAN); });
  RenderSettings s;
  s.width = s.height = 9;
  s.step_voxels = 0.37;
  s.opacity_scale = 6.0;
  s.camera.azimuth_deg = 30;
  s.camera.elevation_deg = 20;
  s.camera.distance = 2.4;
  s.camera.fov_deg = 40;
  const RenderedImage img = render_volume(ctx(), vol, test::random_tf(4, 12), {0, 1}, s);
  ASSERT_EQ(img.rgba.size(), size_t(9 * 9 * 4));
  for (float v : img.rgba) ASSERT_EQ(v, 0.0f);
  EXPECT_GT(img.samples(), 0u) << "rays still march (and count) the empty samples";
}

// A 4 x 4 x 1500 column seen from above through a narrow lens: the rays run its whole height.
// At a step of 0.025 voxels they take 60 002 samples, within llvmpipe's 65535 loop iterations an
// invocation; at 0.01, 150 002 samples, which llvmpipe would end at about 65 000 (the picture 40 %
// paler: before 2026-12-06 it was), so there the renderer marches them in three dispatches, each
// resuming from the state the last one stored. Both match the CPU renderer, stop indices included.
TEST_F(RenderGpu, LongRaysAreMarchedWhole) {
  const Volume vol = test::make_volume({4, 4, 1500}, {1, 1, 1}, "column", [](uint64_t, uint64_t, uint64_t z, uint64_t) {
    return float(0.5 + 0.45 * std::sin(0.05 * double(z)));
  });
  const TransferFunction tf = test::random_tf(8, 5, 0.1, 0.9, 0.2, 0.8);
  RenderSettings s;
  s.width = s.height = 3;
  s.opacity_scale = 2.0;  // at most 2 optical depths over the box: no ray terminates early
  s.termination_opacity = 0.9999;
  s.camera.elevation_deg = 90;
  s.camera.fov_deg = 0.5;
  for (const double step : {0.025, 0.01}) {
    s.step_voxels = step;
    const RenderedImage gpu = render_volume(ctx(), vol, tf, {0, 1}, s);
    const CpuRender cpu = render_cpu(vol, tf, {0, 1}, s);
    ASSERT_EQ(gpu.rgba.size(), cpu.rgba.size());
    EXPECT_GT(cpu.stop[4], step == 0.01 ? 140000u : 55000u) << "the centre ray runs the column's height";
    EXPECT_GT(cpu.rgba[4 * 4 + 3], 0.5) << "the centre ray gathers most of its opacity along the column";
    for (size_t p = 0; p < cpu.stop.size(); ++p) EXPECT_EQ(gpu.stop[p], cpu.stop[p]) << "step " << step << ", pixel " << p;
    for (size_t k = 0; k < cpu.rgba.size(); ++k)
      EXPECT_NEAR(gpu.rgba[k], cpu.rgba[k], 2e-3) << "step " << step << ", value " << k;
  }
}

// A command whose rays are longer than llvmpipe lets one invocation march: there it exits 1 with
// each of `phrases` in its message and writes nothing at `output`; on devices without a loop
// limit it runs.
void expect_refused_where_loops_are_limited(const Context& ctx, const test::CliResult& r,
                                            std::initializer_list<const char*> phrases, const std::string& output) {
  if (ctx.loop_iteration_limit() == 0) {
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return;
  }
  EXPECT_EQ(r.exit_code, 1) << r.output;
  for (const char* phrase : phrases) EXPECT_NE(r.output.find(phrase), std::string::npos) << phrase << "\n" << r.output;
  EXPECT_FALSE(std::filesystem::exists(output)) << "nothing is written";
}

// `tfmatch optimize` of an 8 x 8 x 2000 column against itself at a step of 0.02 voxels (rays of
// 100 004 samples) with `solver_options`, writing dir/tf.json.
test::CliResult optimize_column(const test::TempDir& dir, const std::string& solver_options) {
  std::vector<float> column(8 * 8 * 2000);
  for (size_t i = 0; i < column.size(); ++i) column[i] = float((i / 64) % 50) / 49.0f;
  const std::string file = dir / "column_8x8x2000_float32.raw";
  test::write_floats(file, column);
  return test::run_cli("optimize --ref " + file + " --ref-tf grey --field " + file + " --out " + dir / "tf.json" +
                       " --step 0.02 " + solver_options);
}

// The check every marching kernel makes counts all the rays one invocation marches and its other
// loops: exactly at the limit it passes, one sample more is refused naming the count and a step
// that fits (which passes); devices without a known limit pass everything.
TEST_F(RenderGpu, MarchLoopCheckCountsEveryRayOfAnInvocation) {
  const uint64_t limit = ctx().loop_iteration_limit();
  gpu::RenderPush push{};
  push.dt = 0.01f;
  for (const uint32_t rays : {1u, 4u}) {
    const uint64_t other = 2 * 1024 + 8;
    // rays (max_steps + 1) + other + 256 == limit, or the largest below when it does not divide.
    const uint32_t at_limit = limit ? uint32_t((limit - other - 256) / rays - 1) : 1000000u;
    push.max_steps = at_limit;
    EXPECT_NO_THROW(check_march_loops(ctx(), push, rays, other, "test")) << rays << " rays";
    push.max_steps = at_limit + 1;
    if (limit == 0) {
      EXPECT_NO_THROW(check_march_loops(ctx(), push, rays, other, "test"));
      continue;
    }
    try {
      check_march_loops(ctx(), push, rays, other, "test");
      ADD_FAILURE() << rays << " rays of " << push.max_steps << " samples passed";
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind("test: rays of up to " + std::to_string(at_limit + 1) + " samples", 0), 0u) << what;
      EXPECT_EQ(what.find(" loop iterations a sample in one shader invocation") != std::string::npos, rays > 1) << what;
      const size_t at = what.find("a step of at least ");
      ASSERT_NE(at, std::string::npos) << what;
      // The step named gives a diagonal of (max_steps - 2) dt in fewer samples: it passes.
      const double step = std::stod(what.substr(at + 18));
      gpu::RenderPush fitting = push;
      fitting.max_steps = uint32_t(std::ceil(double(push.max_steps - 2) * push.dt / step)) + 2;
      EXPECT_NO_THROW(check_march_loops(ctx(), fitting, rays, other, "test")) << what;
    }
  }
}

// DiffDVR marches rays of any length: on llvmpipe, rays longer than one invocation may loop (an
// 8 x 8 x 2000 column at 0.02 voxels: 100 004 samples, refused before 2026-12-06) are marched
// forward and back in parts; the fit runs and writes its TF on every device.
TEST_F(RenderGpu, DiffDvrMarchesRaysLongerThanOneInvocationMayLoop) {
  const test::TempDir dir;
  const test::CliResult r = optimize_column(dir, "--solver diffdvr --image-size 8 --iterations 2");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir / "tf.json"));
}

// The visibility weights march rays of any length: on llvmpipe, rays longer than one invocation
// may loop (an 8 x 8 x 2000 column at 0.02 voxels: 100 004 samples, refused before 2026-12-06)
// one view at a time in parts; the weighted fit runs and writes its TF on every device.
TEST_F(RenderGpu, VisibilityWeightsMarchRaysLongerThanOneInvocationMayLoop) {
  const test::TempDir dir;
  const test::CliResult r = optimize_column(dir, "--solver normal-equations --weights visibility");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir / "tf.json"));
}

}  // namespace
}  // namespace tfm
