// GPU renderer beyond its case table (host/selftest/selftest_render.cpp, run by
// test_kernel_cases.cpp: awkward grids and images, anisotropic spacing, seven cameras including
// both poles, NaNs, fields in several chunks, early termination and the inverse-march check, each
// against the double-precision CPU renderer): a field of NaN only is transparent and its rays
// still march.
#include <algorithm>
#include <cmath>

#include "render.h"
#include "test_data.h"
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

}  // namespace
}  // namespace tfm
