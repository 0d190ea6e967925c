// Orbit camera and ray setup (CPU): an orthonormal, continuous basis at every elevation, the
// poles included; the box scaled by spacing; image orientation; settings validation.
#include <gtest/gtest.h>

#include <cmath>

#include "tfmatch/model/camera.h"
#include "tfmatch/reference/cpu_renderer.h"

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
  s = {};
  s.z_scale = 0.0;
  expect_rejected(s, "z scale");
  // Spacings ten orders apart (a file's coordinates in other units per axis): the message says so,
  // with the grid and the spacings' ratios, not only "step too small" (which --step cannot mend).
  const VolumeGeometry uneven = VolumeGeometry::from({4, 3, 2}, {1e-10, 1, 1});
  try {
    march_constants(RenderSettings{}, uneven);
    ADD_FAILURE() << "rays of 10^10 samples accepted";
  } catch (const std::runtime_error& e) {
    for (const char* word :
         {"over 10^8 samples", "grid 4x3x2", "each axis's spacing 1, 1e+10, 1e+10", "spacing or coordinates"})
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
  }
}

TEST(RenderCamera, ZScaleStretchesTheVerticalOnly) {
  const VolumeGeometry g = VolumeGeometry::from({10, 20, 4}, {2.5, 2.5, 1.0}, 10.0);
  // z becomes 10 per level, the finest axis is now x/y at 2.5: world units of 2.5.
  EXPECT_DOUBLE_EQ(g.axis_scale.x, 1.0);
  EXPECT_DOUBLE_EQ(g.axis_scale.z, 4.0);
  EXPECT_DOUBLE_EQ(g.half_extent().z, 8.0);
  EXPECT_THROW(VolumeGeometry::from({2, 2, 2}, {1, 1, 1}, -1.0), std::runtime_error);
}

// The projected box corners of a frame, as the fraction of the image's half-width/half-height
// the farthest one reaches (x and y separately).
std::pair<double, double> corner_reach(const CameraFrame& f, const VolumeGeometry& g, uint32_t w, uint32_t h) {
  double rx = 0, ry = 0;
  for (int c = 0; c < 8; ++c) {
    const glm::dvec3 p(c & 1 ? g.dims[0] - 0.5 : -0.5, c & 2 ? g.dims[1] - 0.5 : -0.5, c & 4 ? g.dims[2] - 0.5 : -0.5);
    const auto q = project_to_pixel(f, g, p, w, h);
    EXPECT_TRUE(q.has_value());
    if (!q) continue;
    rx = std::max(rx, std::abs((q->x + 0.5) / (0.5 * w) - 1.0));
    ry = std::max(ry, std::abs((q->y + 0.5) / (0.5 * h) - 1.0));
  }
  return {rx, ry};
}

TEST(RenderCamera, DefaultCameraFramesBoxesOfEveryShape) {
  // A cube, a thin geophysical slab (GFS: 144 x 73 x 26 at 2.5 degrees, levels 1 apart), a tall
  // column, on square and wide images, from several poses: every corner inside the image, and
  // the box touching the 94 % margin on one side (so it is as large as it can be).
  struct Box {
    std::array<uint64_t, 3> dims;
    std::array<double, 3> spacing;
  };
  for (const Box& b : {Box{{16, 16, 16}, {1, 1, 1}}, Box{{144, 73, 26}, {2.5, 2.5, 1}}, Box{{5, 7, 90}, {1, 1, 1}}})
    for (auto [w, h] : {std::pair{64u, 64u}, std::pair{160u, 48u}})
      for (auto [az, el] : {std::pair{30.0, 20.0}, std::pair{-100.0, 60.0}, std::pair{0.0, 90.0}}) {
        SCOPED_TRACE(std::to_string(b.dims[0]) + "x" + std::to_string(b.dims[2]) + " image " + std::to_string(w) + "x" +
                     std::to_string(h) + " az " + std::to_string(az) + " el " + std::to_string(el));
        const VolumeGeometry g = VolumeGeometry::from(b.dims, b.spacing);
        OrbitCamera cam;
        cam.azimuth_deg = az;
        cam.elevation_deg = el;
        ASSERT_EQ(cam.distance, 0.0) << "framing is the default";
        const auto [rx, ry] = corner_reach(orbit_frame(cam, g, w, h), g, w, h);
        EXPECT_LE(rx, 0.94 + 1e-9);
        EXPECT_LE(ry, 0.94 + 1e-9);
        EXPECT_NEAR(std::max(rx, ry), 0.94, 0.01);
      }
  // The thin slab, seen from the default pose on a square image, spans the image's width.
  const VolumeGeometry slab = VolumeGeometry::from({144, 73, 26}, {2.5, 2.5, 1});
  EXPECT_NEAR(corner_reach(orbit_frame(OrbitCamera{}, slab, 64, 64), slab, 64, 64).first, 0.94, 0.01);
}

TEST(RenderCamera, BoxOutlineIsDrawnUnlessTurnedOff) {
  const VolumeGeometry g = VolumeGeometry::from({12, 8, 4}, {1, 1, 1});
  RenderSettings s;
  s.width = 80;
  s.height = 60;
  Image img(80, 60);
  draw_box_outline(img, g, s);
  // Every projected corner pixel is on the outline.
  const CameraFrame f = orbit_frame(s.camera, g, 80, 60);
  for (int c = 0; c < 8; ++c) {
    const glm::dvec3 p(c & 1 ? 11.5 : -0.5, c & 2 ? 7.5 : -0.5, c & 4 ? 3.5 : -0.5);
    const auto q = project_to_pixel(f, g, p, 80, 60);
    ASSERT_TRUE(q);
    const uint8_t* px = img.at(uint32_t(std::lround(q->x)), uint32_t(std::lround(q->y)));
    EXPECT_LT(px[0], 230) << "corner " << c;
  }
  size_t grey = 0;
  for (uint8_t v : img.rgb) grey += v < 255;
  EXPECT_GT(grey, 100u);
  // The edges from voxel (0, 0, 0)'s corner are the axes: red x, green y, blue z at their middles,
  // each named by a letter of its colour beyond its end (a camera further off leaves them room).
  RenderSettings far = s;
  far.camera.distance = 4.5;
  Image axes(160, 120);
  draw_box_outline(axes, g, far);
  const CameraFrame ff = orbit_frame(far.camera, g, 160, 120);
  // How strongly channel k stands out near (x, y): the most over the other two within `r` pixels.
  auto tint = [&](glm::dvec2 at, int k, int r) {
    int best = -255;
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        const int x = int(at.x) + dx, y = int(at.y) + dy;
        if (x < 0 || y < 0 || x >= 160 || y >= 120) continue;
        const uint8_t* q = axes.at(uint32_t(x), uint32_t(y));
        best = std::max(best, int(q[k]) - std::max(int(q[(k + 1) % 3]), int(q[(k + 2) % 3])));
      }
    return best;
  };
  const glm::dvec3 origin(-0.5, -0.5, -0.5), ends[3] = {{11.5, -0.5, -0.5}, {-0.5, 7.5, -0.5}, {-0.5, -0.5, 3.5}};
  const auto o = project_to_pixel(ff, g, origin, 160, 120);
  ASSERT_TRUE(o);
  for (int k = 0; k < 3; ++k) {
    const auto e = project_to_pixel(ff, g, ends[k], 160, 120);
    ASSERT_TRUE(e);
    EXPECT_GT(tint((*o + *e) * 0.5, k, 1), 40) << "axis " << k << " is not in its colour";
    EXPECT_GT(tint(*e + glm::normalize(*e - *o) * 8.0, k, 3), 40) << "no letter beyond axis " << k << " at " << e->x << "," << e->y;
  }
  Image off(80, 60);
  s.box_outline = false;
  draw_box_outline(off, g, s);
  for (uint8_t v : off.rgb) ASSERT_EQ(v, 255);
}

}  // namespace
}  // namespace tfm
