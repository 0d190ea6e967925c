// Grid points from text (indices and coordinates), marker projection and drawing.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "tfmatch/kernels/render.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/image.h"

namespace tfm {
namespace {

// A 6x4x3 grid with longitudes 0..300 (step 60), latitudes 90..-90 (decreasing) and pressure levels.
Volume geo_grid() {
  Volume v;
  v.dims = {6, 4, 3};
  v.name = "geo";
  v.axes[0] = {"longitude", "degrees_east", {0, 60, 120, 180, 240, 300}};
  v.axes[1] = {"latitude", "degrees_north", {90, 30, -30, -90}};
  v.axes[2] = {"isobaricInhPa", "hPa", {250, 500, 850}};
  return v;
}

template <class F>
std::string error_of(F f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(GridPoint, IndicesAreCheckedAgainstTheGrid) {
  const Volume g = geo_grid();
  EXPECT_EQ(resolve_grid_point(g, "5,3,2", "--point"), (GridIndex{5, 3, 2}));
  EXPECT_EQ(resolve_grid_point(g, " 0, 1 ,2", "--point"), (GridIndex{0, 1, 2}));
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "6,0,0", "--point"); }).find("outside the grid 6x4x3"), std::string::npos);
  for (const char* bad : {"1,2", "1,2,3,4", "-1,0,0", "a,b,c", "1.5,0,0", ""})
    EXPECT_NE(error_of([&] { resolve_grid_point(g, bad, "--point"); }).find("expected I,J,K"), std::string::npos) << bad;
}

TEST(GridPoint, CoordinatesPickTheNearestPointPerAxis) {
  const Volume g = geo_grid();
  EXPECT_EQ(resolve_grid_point(g, "lon=125,lat=-20,level=500", "--point"), (GridIndex{2, 2, 1}));
  // Longitudes wrap: 350 is nearest to 0, -65 to 300; axis names work as keys.
  EXPECT_EQ(resolve_grid_point(g, "lon=350,lat=90,isobaricInhPa=850", "--point"), (GridIndex{0, 0, 2}));
  EXPECT_EQ(resolve_grid_point(g, "longitude=-65,latitude=-90,z=250", "--point"), (GridIndex{5, 3, 0}));
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "lon=10,lat=0", "--point"); }).find("no coordinate for axis z"),
            std::string::npos);
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "lon=10,lat=0,level=2000", "--point"); }).find("outside"),
            std::string::npos);
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "lon=10,lat=0,height=x", "--point"); }).find("not a number"),
            std::string::npos);
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "lon=10,lat=0,lev=500,lon=20", "--point"); }).find("given twice"),
            std::string::npos);
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "time=3,lat=0,level=500", "--point"); }).find("names no axis"),
            std::string::npos);
  EXPECT_EQ(describe_grid_point(g, {2, 2, 1}), "(2, 2, 1) at longitude=120, latitude=-30, isobaricInhPa=500");
}

// A coordinate just past an axis's end (within a step: levels 250..850 step 300) is the end, and
// said so; one inside the axis is the nearest point, silently; further out is an error.
TEST(GridPoint, CoordinatesJustPastAnEndAreThatEndWithAWarning) {
  const Volume g = geo_grid();
  std::vector<std::string> warnings;
  EXPECT_EQ(resolve_grid_point(g, "lon=0,lat=90,level=1000", "--point", &warnings), (GridIndex{0, 0, 2}));
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0], "--point 'lon=0,lat=90,level=1000': level=1000 lies outside geo's isobaricInhPa range 250 .. 850; "
                         "the nearest, 850, is used");
  warnings.clear();
  EXPECT_EQ(resolve_grid_point(g, "lon=0,lat=100,level=700", "--point", &warnings), (GridIndex{0, 0, 2}));
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("lat=100 lies outside geo's latitude range -90 .. 90; the nearest, 90, is used"),
            std::string::npos) << warnings[0];
  warnings.clear();
  EXPECT_EQ(resolve_grid_point(g, "lon=0,lat=-90,level=850", "--point", &warnings), (GridIndex{0, 3, 2}));
  EXPECT_EQ(resolve_grid_point(g, "lon=0,lat=10,level=600", "--point", &warnings), (GridIndex{0, 1, 1}));
  EXPECT_TRUE(warnings.empty()) << warnings[0];
  EXPECT_EQ(error_of([&] { resolve_grid_point(g, "lon=0,lat=0,level=1200", "--point", &warnings); }),
            "--point 'lon=0,lat=0,level=1200': level=1200 is outside geo's isobaricInhPa range 250 .. 850");
}

TEST(GridPoint, AxesWithoutCoordinatesUseOriginAndSpacing) {
  Volume g;
  g.dims = {10, 1, 5};
  g.origin = {100, 0, -2};
  g.spacing = {0.5, 1, 2};
  g.name = "plain";
  EXPECT_EQ(resolve_grid_point(g, "x=102.2,z=4.4", "--point"), (GridIndex{4, 0, 3}));  // y has one point
  EXPECT_NE(error_of([&] { resolve_grid_point(g, "x=200,z=0", "--point"); }).find("outside"), std::string::npos);
  Volume bare;
  bare.dims = {4, 4, 4};
  bare.name = "bare";
  EXPECT_EQ(resolve_grid_point(bare, "x=2,y=3,z=1", "--point"), (GridIndex{2, 3, 1}));
}

// A voxel projected to a pixel lies on that pixel's ray, for cameras all around the box and a
// non-cubic grid with anisotropic spacing.
TEST(Markers, ProjectionInvertsThePixelRays) {
  const VolumeGeometry geo = VolumeGeometry::from({40, 24, 9}, {1.0, 1.5, 3.0});
  RenderSettings s;
  s.width = 160;
  s.height = 120;
  const glm::dvec3 point(31, 5, 7);
  for (double az : {0.0, 75.0, 200.0})
    for (double el : {-60.0, 10.0, 89.0}) {
      s.camera.azimuth_deg = az;
      s.camera.elevation_deg = el;
      const CameraFrame f = orbit_frame(s.camera, geo, s.width, s.height);
      const auto p = project_to_pixel(f, geo, point, s.width, s.height);
      ASSERT_TRUE(p) << az << " " << el;
      // Direction through the (fractional) pixel, as pixel_ray builds it.
      const double sx = ((2.0 * (p->x + 0.5)) / s.width - 1.0) * f.tan_half_fov * f.aspect;
      const double sy = (1.0 - (2.0 * (p->y + 0.5)) / s.height) * f.tan_half_fov;
      const glm::dvec3 dir = glm::normalize(f.forward + sx * f.right + sy * f.up);
      const glm::dvec3 to_point = point * geo.axis_scale - f.eye;
      const double off_ray = glm::length(to_point - glm::dot(to_point, dir) * dir);
      EXPECT_LT(off_ray, 1e-9 * glm::length(to_point)) << az << " " << el;
    }
  // Behind the eye: nothing.
  s.camera = {};
  const CameraFrame f = orbit_frame(s.camera, geo, s.width, s.height);
  EXPECT_FALSE(project_to_pixel(f, geo, f.eye / geo.axis_scale - 10.0 * f.forward / geo.axis_scale, s.width, s.height));
}

TEST(Markers, DotsAreDrawnRedWhereTheVoxelProjects) {
  const VolumeGeometry geo = VolumeGeometry::from({32, 32, 16}, {1, 1, 1});
  RenderSettings s;
  s.width = 200;
  s.height = 150;
  Image img(s.width, s.height, {255, 255, 255});
  const std::array<uint64_t, 3> voxel{8, 20, 3};
  draw_markers(img, geo, s, {voxel});
  const auto p = project_to_pixel(orbit_frame(s.camera, geo, s.width, s.height), geo, glm::dvec3(8, 20, 3), s.width,
                                  s.height);
  ASSERT_TRUE(p);
  const uint8_t* c = img.at(uint32_t(std::lround(p->x)), uint32_t(std::lround(p->y)));
  EXPECT_GT(c[0], 200);
  EXPECT_LT(c[1], 60);
  EXPECT_LT(c[2], 60);
  // Far from the dot the image is untouched.
  const uint8_t* far = img.at(uint32_t(std::lround(p->x)) + 20 < s.width ? uint32_t(std::lround(p->x)) + 20 : 0,
                              uint32_t(std::lround(p->y)));
  EXPECT_EQ(far[1], 255);
  Image none(s.width, s.height, {255, 255, 255});
  draw_markers(none, geo, s, {});
  EXPECT_EQ(none.rgb, Image(s.width, s.height, {255, 255, 255}).rgb);
}

}  // namespace
}  // namespace tfm
