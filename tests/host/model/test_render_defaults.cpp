// The grid-dependent picture defaults: which grids are thin, and what a thin grid's pictures
// default to (from above, north up, opacity per box height, the map's aspect) unless chosen.
#include <gtest/gtest.h>

#include <string>

#include "tfmatch/model/camera.h"
#include "tfmatch/model/render_defaults.h"

namespace tfm {
namespace {

TEST(RenderDefaults, ThinGridsAreFewLevelsOrFlatBoxes) {
  EXPECT_TRUE(is_thin_grid({120, 61, 2}, {3.0, 3.0, 1.0}, 1.0));     // ERA5 ensemble: two levels
  EXPECT_TRUE(is_thin_grid({128, 64, 14}, {2.8, 2.8, 1.0}, 1.0));    // 14 levels, 25x wider than tall
  EXPECT_TRUE(is_thin_grid({64, 64, 4}, {1.0, 1.0, 10.0}, 1.0));     // 4 levels, however tall
  EXPECT_FALSE(is_thin_grid({96, 96, 96}, {1.0, 1.0, 1.0}, 1.0));    // the demo cube
  EXPECT_FALSE(is_thin_grid({125, 125, 25}, {1.0, 1.0, 1.0}, 1.0));  // 1/5 as tall: a volume
  EXPECT_FALSE(is_thin_grid({128, 64, 14}, {2.8, 2.8, 1.0}, 20.0));  // exaggerated: no longer flat
}

TEST(RenderDefaults, AThinGridIsAMapFromAboveWithOpacityPerHeight) {
  RenderSettings s;
  const std::string note = apply_grid_defaults(s, {120, 61, 2}, {3.0, 3.0, 1.0}, {});
  // The note says what was set and the factor, so that a user's own scale can be given scaled.
  EXPECT_EQ(note, "a thin grid (120x61x2): seen from above, north up; opacity scale 20 x box length / height 180 = "
                  "3600 (--opacity-scale sets the scale itself); 512x260 pixels, the map's aspect");
  EXPECT_EQ(s.camera.elevation_deg, 90.0);
  EXPECT_EQ(s.camera.azimuth_deg, -90.0);
  // A ray down through the two levels meets the optical depth of a ray through a cube: the
  // box is 360 long and 2 high.
  EXPECT_DOUBLE_EQ(s.opacity_scale, 20.0 * 360.0 / 2.0);
  EXPECT_EQ(s.width, 512u);
  EXPECT_EQ(s.height, 260u);  // 512 * 183 / 360
  // North up, east to the right: the frame's up is +y and right is +x.
  const CameraFrame f = orbit_frame(s.camera, VolumeGeometry::from({120, 61, 2}, {3.0, 3.0, 1.0}), s.width, s.height);
  EXPECT_NEAR(f.up.y, 1.0, 1e-12);
  EXPECT_NEAR(f.right.x, 1.0, 1e-12);
  EXPECT_NEAR(f.forward.z, -1.0, 1e-12);
}

TEST(RenderDefaults, ChosenSettingsAndOtherGridsStayAsTheyAre) {
  RenderSettings chosen;
  chosen.camera.elevation_deg = 35.0;
  chosen.opacity_scale = 7.0;
  chosen.width = 300;
  EXPECT_EQ(apply_grid_defaults(chosen, {120, 61, 2}, {3.0, 3.0, 1.0}, {true, true, true}), "");
  EXPECT_EQ(chosen.camera.elevation_deg, 35.0);
  EXPECT_EQ(chosen.camera.azimuth_deg, 30.0);
  EXPECT_EQ(chosen.opacity_scale, 7.0);
  EXPECT_EQ(chosen.width, 300u);
  EXPECT_EQ(chosen.height, 512u);
  // Angles chosen: the picture keeps its size (a map's aspect is for the view from above).
  RenderSettings angles;
  apply_grid_defaults(angles, {120, 61, 2}, {3.0, 3.0, 1.0}, {true, false, false});
  EXPECT_EQ(angles.width, 512u);
  EXPECT_EQ(angles.height, 512u);
  EXPECT_DOUBLE_EQ(angles.opacity_scale, 3600.0);
  RenderSettings cube;
  EXPECT_EQ(apply_grid_defaults(cube, {96, 96, 96}, {1.0, 1.0, 1.0}, {}), "");
  EXPECT_EQ(cube.camera.elevation_deg, RenderSettings{}.camera.elevation_deg);
  EXPECT_EQ(cube.opacity_scale, RenderSettings{}.opacity_scale);
  EXPECT_EQ(cube.height, 512u);
}

}  // namespace
}  // namespace tfm
