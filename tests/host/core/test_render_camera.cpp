// Orbit camera and ray setup (CPU): an orthonormal, continuous basis at every elevation, the
// poles included; the box scaled by spacing; image orientation; settings validation.
#include <gtest/gtest.h>

#include <cmath>

#include "camera.h"
#include "cpu_renderer.h"

namespace tfm {
namespace {

void expect_orthonormal(const CameraFrame& f) {
  EXPECT_NEAR(glm::length(f.forward), 1.0, 1e-12);
  EXPECT_NEAR(glm::length(f.right), 1.0, 1e-12);
  EXPECT_NEAR(glm::length(f.up), 1.0, 1e-12);
  EXPECT_NEAR(glm::dot(f.forward, f.right), 0.0, 1e-12);
  EXPECT_NEAR(glm::dot(f.forward, f.up), 0.0, 1e-12);
  EXPECT_NEAR(glm::dot(f.right, f.up), 0.0, 1e-12);
  EXPECT_LT(glm::length(glm::cross(f.forward, f.up) - f.right), 1e-12) << "right-handed: right = forward x up";
}

TEST(RenderCamera, BasisIsOrthonormalAtEveryElevationIncludingThePoles) {
  const VolumeGeometry g = VolumeGeometry::from({20, 10, 5}, {1, 1, 1});
  for (double az : {0.0, 37.0, 180.0, -90.0, 725.0})
    for (double el = -90; el <= 90; el += 7.5) {
      SCOPED_TRACE("azimuth " + std::to_string(az) + " elevation " + std::to_string(el));
      OrbitCamera cam{az, el, 3.0, 30.0};
      const CameraFrame f = orbit_frame(cam, g, 64, 48);
      expect_orthonormal(f);
      // The eye sits at distance * radius from the box centre and looks at it.
      EXPECT_NEAR(glm::length(f.eye - g.center()), 3.0 * g.radius(), 1e-9);
      EXPECT_LT(glm::length(glm::normalize(g.center() - f.eye) - f.forward), 1e-12);
    }
}

TEST(RenderCamera, BasisIsContinuousIntoThePoles) {
  const VolumeGeometry g = VolumeGeometry::from({8, 8, 8}, {1, 1, 1});
  for (double pole : {90.0, -90.0}) {
    const CameraFrame at = orbit_frame({30, pole, 3, 30}, g, 8, 8);
    const CameraFrame near = orbit_frame({30, pole - std::copysign(1e-6, pole), 3, 30}, g, 8, 8);
    EXPECT_LT(glm::length(at.up - near.up), 1e-7);
    EXPECT_LT(glm::length(at.right - near.right), 1e-7);
    // Straight down (up) the z axis.
    EXPECT_NEAR(at.forward.z, pole > 0 ? -1.0 : 1.0, 1e-12);
  }
}

TEST(RenderCamera, BoxIsScaledBySpacing) {
  const VolumeGeometry g = VolumeGeometry::from({10, 20, 4}, {0.5, 0.5, 2.0});
  EXPECT_DOUBLE_EQ(g.axis_scale.z, 4.0);  // world unit = one voxel of the finest axis
  EXPECT_DOUBLE_EQ(g.half_extent().x, 5.0);
  EXPECT_DOUBLE_EQ(g.half_extent().y, 10.0);
  EXPECT_DOUBLE_EQ(g.half_extent().z, 8.0);
  EXPECT_DOUBLE_EQ(g.box_length(), 20.0);
  EXPECT_DOUBLE_EQ(g.center().z, 1.5 * 4.0);  // voxel centres at index 0..3
  EXPECT_THROW(VolumeGeometry::from({10, 0, 4}, {1, 1, 1}), std::runtime_error);
  EXPECT_THROW(VolumeGeometry::from({10, 1, 4}, {1, -1, 1}), std::runtime_error);
}

TEST(RenderCamera, CentrePixelRayCrossesTheBoxThroughItsCentre) {
  const VolumeGeometry g = VolumeGeometry::from({9, 7, 5}, {1, 1, 1});
  RenderSettings s;
  s.camera = {0, 0, 4, 30};  // on the +x axis: the ray runs along -x through 9 voxels
  const MarchConstants m = march_constants(s, g);
  const CameraFrame f = orbit_frame(s.camera, g, 11, 11);
  const RaySegment r = pixel_ray(f, g, m, 5, 5, 11, 11);
  EXPECT_NEAR(r.t_exit - r.t_entry, 9.0, 1e-9);
  EXPECT_EQ(r.steps, 18u);
  EXPECT_NEAR(r.entry.x, 8.5, 1e-9);
  EXPECT_NEAR(r.entry.y, 3.0, 1e-9);
  EXPECT_NEAR(r.entry.z, 2.0, 1e-9);
  // A narrow view's corner ray misses a distant box.
  s.camera = {0, 0, 40, 20};
  const RaySegment miss = pixel_ray(orbit_frame(s.camera, g, 11, 11), g, m, 0, 0, 11, 11);
  EXPECT_EQ(miss.steps, 0u);
}

TEST(RenderCamera, ImageRowsRunTopToBottomAndColumnsLeftToRight) {
  // Opaque only where z is high (top) and y is high: from +x (azimuth 0, elevation 0) with
  // right = +y and up = +z, the opaque quadrant is the image's top right.
  Volume v;
  v.dims = {8, 8, 8};
  v.values.resize(512);
  for (uint64_t z = 0; z < 8; ++z)
    for (uint64_t y = 0; y < 8; ++y)
      for (uint64_t x = 0; x < 8; ++x) v.values[(z * 8 + y) * 8 + x] = (z >= 4 && y >= 4) ? 1.0f : 0.0f;
  TransferFunction tf{{{1, 1, 1, 0}, {1, 1, 1, 1}}, std::nullopt};
  RenderSettings s;
  s.width = s.height = 16;
  s.camera = {0, 0, 3, 30};
  const CpuRender img = render_cpu(v, tf, {0, 1}, s);
  auto alpha = [&](uint32_t x, uint32_t y) { return img.rgba[4 * (size_t(y) * 16 + x) + 3]; };
  EXPECT_GT(alpha(11, 4), 0.5);   // top right
  EXPECT_LT(alpha(4, 11), 0.05);  // bottom left
  EXPECT_LT(alpha(4, 4), 0.05);   // top left
  EXPECT_LT(alpha(11, 11), 0.05); // bottom right
}

TEST(RenderCamera, InvalidSettingsAreRejectedWithTheirName) {
  const VolumeGeometry g = VolumeGeometry::from({4, 4, 4}, {1, 1, 1});
  auto expect_rejected = [&](RenderSettings s, const std::string& word) {
    try {
      march_constants(s, g);
      ADD_FAILURE() << "accepted invalid " << word;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  RenderSettings s;
  s.camera.elevation_deg = 90.5;
  expect_rejected(s, "elevation");
  s = {};
  s.termination_opacity = 1.0;
  expect_rejected(s, "termination");
  s = {};
  s.camera.distance = 1.0;
  expect_rejected(s, "distance");
  s = {};
  s.width = 0;
  expect_rejected(s, "image size");
  s = {};
  s.step_voxels = 0.0;
  expect_rejected(s, "step");
  s = {};
  s.background = {1.5, 0, 0};
  expect_rejected(s, "background");
}

}  // namespace
}  // namespace tfm
