// The optical model against closed forms: a slab of constant extinction gives 1 - exp(-sigma L)
// on the GPU and in the CPU reference, and compositing is premultiplied front to back.
#include <algorithm>
#include <cmath>

#include "tfmatch/kernels/render.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

// A constant field and a TF whose two entries are equal: every sample has colour c, opacity a.
Volume constant_volume(std::array<uint64_t, 3> dims, std::array<double, 3> spacing) {
  Volume v;
  v.dims = dims;
  v.spacing = spacing;
  v.values.assign(v.voxel_count(), 0.5f);
  return v;
}

TransferFunction constant_tf(Rgba c) { return TransferFunction{{c, c}, std::nullopt}; }

class RenderOptics : public test::GpuTest {};

TEST_F(RenderOptics, SlabMatchesOneMinusExpSigmaL) {
  // 6 x 6 x 8 voxels, z spacing 1: the box is 8 world units tall, its longest side, so a ray
  // straight down the z axis crosses L = 1 box length and alpha = 1 - exp(-a * scale).
  const Volume vol = constant_volume({6, 6, 8}, {1, 1, 1});
  const Rgba c{0.2, 0.6, 0.9, 0.3};
  RenderSettings s;
  s.width = s.height = 9;  // odd: the centre pixel's ray is the box axis
  s.step_voxels = 0.5;     // 16 steps: L is a whole number of steps
  s.opacity_scale = 4.0;
  s.camera.elevation_deg = 90;
  s.camera.fov_deg = 20;
  const double sigma_l = c[3] * s.opacity_scale * 1.0;
  const double alpha = 1.0 - std::exp(-sigma_l);
  const size_t centre = 4 * 9 + 4;

  const RenderedImage gpu = render_volume(ctx(), vol, constant_tf(c), {0, 1}, s);
  const CpuRender cpu = render_cpu(vol, constant_tf(c), {0, 1}, s);
  // The CPU reference is exact up to double rounding; the GPU evaluates exp and 16 products of
  // the transmittance in float (a few ulp each): 1e-5.
  EXPECT_NEAR(cpu.rgba[4 * centre + 3], alpha, 1e-12);
  EXPECT_NEAR(gpu.rgba[4 * centre + 3], alpha, 1e-5);
  for (int ch = 0; ch < 3; ++ch) {
    EXPECT_NEAR(cpu.rgba[4 * centre + ch], c[ch] * alpha, 1e-12) << "premultiplied colour, channel " << ch;
    EXPECT_NEAR(gpu.rgba[4 * centre + ch], c[ch] * alpha, 1e-5) << "premultiplied colour, channel " << ch;
  }
  EXPECT_EQ(gpu.stop[centre], 16u);

  // Every other pixel: a constant medium composites to exactly 1 - exp(-sigma L) over its chord L
  // through the box, whatever its sample count K = round(L / dt): each sample weighs L / K (weighed
  // by dt the optical depth jumped by a step where K did: rings on thin slabs).
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing);
  const MarchConstants m = march_constants(s, geo);
  const CameraFrame frame = orbit_frame(s.camera, geo, s.width, s.height);
  for (uint32_t py = 0; py < s.height; ++py)
    for (uint32_t px = 0; px < s.width; ++px) {
      const size_t p = size_t(py) * s.width + px;
      const RaySegment ray = pixel_ray(frame, geo, m, px, py, s.width, s.height);
      const double chord = ray.t_exit - ray.t_entry;
      const double expected = ray.steps == 0 ? 0.0 : 1.0 - std::exp(-c[3] * m.depth_per_alpha * chord / m.dt);
      EXPECT_NEAR(cpu.rgba[4 * p + 3], expected, 1e-12) << px << "," << py;
      if (!ray.steps_ambiguous) EXPECT_NEAR(gpu.rgba[4 * p + 3], expected, 1e-5) << px << "," << py;
      if (ray.t_exit > ray.t_entry) {
        EXPECT_LE(std::abs(ray.steps * m.dt - chord), 0.5 * m.dt + 1e-9);
        if (ray.steps > 0) EXPECT_NEAR(ray.depth_scale * ray.steps * m.dt, chord, 1e-9 * chord);
      } else
        EXPECT_EQ(ray.steps, 0u) << "a ray that misses the box has no samples";
    }
}

TEST(RenderOpticsCpu, OpacityScaleIsPerBoxLength) {
  // The same slab at twice the resolution looks the same: extinction is per box length.
  const Rgba c{1, 1, 1, 0.5};
  RenderSettings s;
  s.width = s.height = 5;
  s.opacity_scale = 3.0;
  s.camera.elevation_deg = -90;  // from below this time
  s.camera.fov_deg = 10;
  const CpuRender coarse = render_cpu(constant_volume({4, 4, 4}, {2, 2, 2}), constant_tf(c), {0, 1}, s);
  const CpuRender fine = render_cpu(constant_volume({8, 8, 8}, {1, 1, 1}), constant_tf(c), {0, 1}, s);
  const size_t centre = 2 * 5 + 2;
  EXPECT_NEAR(coarse.rgba[4 * centre + 3], 1.0 - std::exp(-1.5), 1e-12);
  EXPECT_NEAR(fine.rgba[4 * centre + 3], 1.0 - std::exp(-1.5), 1e-12);
}

TEST_F(RenderOptics, FrontToBackCompositingOfTwoLayers) {
  // Value 0 below z = 3.5, 1 above (linear between the voxel centres z = 3 and 4); the TF maps
  // it to colour (v, 0, 1 - v) at constant opacity 0.5, so every step has the same tau and the
  // premultiplied result is the explicit sum C = sum_k tau^k (1 - tau) c(z_k) in marching order.
  Volume vol = constant_volume({3, 3, 8}, {1, 1, 1});
  for (uint64_t z = 0; z < 8; ++z)
    for (uint64_t i = 0; i < 9; ++i) vol.values[z * 9 + i] = z >= 4 ? 1.0f : 0.0f;
  const TransferFunction tf{{{0, 0, 1, 0.5}, {1, 0, 0, 0.5}}, std::nullopt};
  RenderSettings s;
  s.width = s.height = 3;
  s.step_voxels = 0.25;
  s.opacity_scale = 2.0;
  s.camera.fov_deg = 5;
  const double tau = std::exp(-0.5 * s.opacity_scale * s.step_voxels / 8.0);
  for (double elevation : {90.0, -90.0}) {
    SCOPED_TRACE(elevation);
    s.camera.elevation_deg = elevation;
    double red = 0, blue = 0, t = 1;
    for (int k = 0; k < 32; ++k) {
      const double z = elevation > 0 ? 7.5 - (k + 0.5) * 0.25 : -0.5 + (k + 0.5) * 0.25;
      const double v = std::clamp(z - 3.0, 0.0, 1.0);
      red += t * (1 - tau) * v;
      blue += t * (1 - tau) * (1 - v);
      t *= tau;
    }
    const RenderedImage gpu = render_volume(ctx(), vol, tf, {0, 1}, s);
    const size_t centre = 4;
    // float exp and 32 steps of float compositing: a few ulp each, 1e-5 overall.
    EXPECT_NEAR(gpu.rgba[4 * centre + 0], red, 1e-5);
    EXPECT_NEAR(gpu.rgba[4 * centre + 2], blue, 1e-5);
    EXPECT_NEAR(gpu.rgba[4 * centre + 3], 1 - t, 1e-5);
    // The layer in front dominates.
    EXPECT_GT(elevation > 0 ? red : blue, 1.5 * (elevation > 0 ? blue : red));
  }
}

}  // namespace
}  // namespace tfm
