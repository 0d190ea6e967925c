// Coordinate ticks: round values at the steps maps use, labels as maps write them, where a value
// lies among an axis's coordinates, and the ticks a rendering of a lat/lon grid gets along its
// box's edges (none without coordinates, the same pixels whatever text face is installed).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "tfmatch/model/axis_ticks.h"
#include "tfmatch/model/camera.h"

namespace tfm {
namespace {

GridAxis axis(const std::string& name, const std::string& units, double first, double step, size_t n) {
  GridAxis a{name, units, {}};
  for (size_t i = 0; i < n; ++i) a.coordinates.push_back(first + step * double(i));
  return a;
}

TEST(AxisTicks, LabelsAsMapsWriteThem) {
  const GridAxis lon = axis("longitude", "degrees_east", 0, 2.5, 144), lat = axis("lat", "", -90, 2.5, 73);
  const GridAxis lev = axis("isobaricInhPa", "hPa", 850, -350, 2);
  EXPECT_EQ(coordinate_label(lon, 45), "45E");
  EXPECT_EQ(coordinate_label(lon, 315), "45W");  // 0..360 grids wrap into -180..180
  EXPECT_EQ(coordinate_label(lon, -120), "120W");
  EXPECT_EQ(coordinate_label(lon, 0), "0");
  EXPECT_EQ(coordinate_label(lon, 180), "180");
  EXPECT_EQ(coordinate_label(lat, 30), "30N");
  EXPECT_EQ(coordinate_label(lat, -7.5), "7.5S");
  EXPECT_EQ(coordinate_label(lat, 0), "EQ");
  EXPECT_EQ(coordinate_label(lev, 500), "500");
  // Degree axes step as maps do (45 over 360 degrees), others as nice_ticks.
  EXPECT_EQ(axis_ticks(lon, 0, 357.5, 7), (std::vector<double>{0, 45, 90, 135, 180, 225, 270, 315}));
  EXPECT_EQ(axis_ticks(lat, -90, 90, 4), (std::vector<double>{-90, -45, 0, 45, 90}));
  EXPECT_EQ(axis_ticks(lev, 500, 850, 4), nice_ticks(500, 850, 4));
  EXPECT_EQ(axis_ticks(lat, 44.2, 44.8, 3), nice_ticks(44.2, 44.8, 3));  // finer than a degree
}

TEST(AxisTicks, TickLabelsHoldTheirSignificantDigits) {
  EXPECT_EQ(tick_label(0.25), "0.25");
  EXPECT_EQ(tick_label(1234.5), "1234");
  EXPECT_EQ(tick_label(1234.5, 3), "1.23e+03");
  EXPECT_EQ(tick_label(15000), "1.5e+04");
  EXPECT_EQ(tick_label(-0.5, 3), "-0.5");
  // Coordinates a step's sum leaves a hair off zero or 180 still read as maps write them.
  const GridAxis lon{"lon", "degrees_east", {}}, lev{"level", "", {}};
  EXPECT_EQ(coordinate_label(lon, 1e-13), "0");
  EXPECT_EQ(coordinate_label(lon, 180.0 - 1e-12), "180");
  EXPECT_EQ(coordinate_label(lev, -1e-15), "0");
}

TEST(AxisTicks, CoordinateIndexInterpolatesIncreasingAndDecreasingAxes) {
  const GridAxis lat = axis("lat", "degrees_north", -90, 2.5, 73);
  EXPECT_DOUBLE_EQ(*coordinate_index(lat, -90), 0.0);
  EXPECT_DOUBLE_EQ(*coordinate_index(lat, 0), 36.0);
  EXPECT_DOUBLE_EQ(*coordinate_index(lat, 1.25), 36.5);
  EXPECT_FALSE(coordinate_index(lat, 91).has_value());
  const GridAxis lev = axis("lev", "hPa", 1000, -100, 10);  // 1000 .. 100 hPa, decreasing
  EXPECT_DOUBLE_EQ(*coordinate_index(lev, 850), 1.5);
  GridAxis bent = lev;
  bent.coordinates[4] = bent.coordinates[2];  // not monotone: no place for any value
  EXPECT_FALSE(coordinate_index(bent, 950).has_value());
  EXPECT_FALSE(coordinate_index(GridAxis{}, 1.0).has_value());
}

// A 73 x 37 x 2 lat/lon grid (5 degrees, two levels) seen from above, as a map, at 400 x 220.
struct MapView {
  VolumeGeometry geometry = VolumeGeometry::from({73, 37, 2}, {5, 5, 1}, 1.0);
  RenderSettings settings = [] {
    RenderSettings s;
    s.width = 400;
    s.height = 220;
    s.camera.elevation_deg = 90;
    s.camera.azimuth_deg = -90;
    return s;
  }();
  std::array<GridAxis, 3> axes{axis("lon", "degrees_east", 0, 5, 73), axis("lat", "degrees_north", -90, 5, 37),
                               axis("lev", "hPa", 850, -350, 2)};
};

// A 73 x 37 x 2 lat/lon grid seen from above, as a map: labels on the south and west edges (the
// x and y axis edges), in the fixed font, whatever face is installed; nothing without coordinates.
TEST(AxisTicks, AMapRenderingGetsLabelledTicksAlongItsAxisEdges) {
  const MapView m;
  const VolumeGeometry& g = m.geometry;
  const RenderSettings& s = m.settings;
  const std::array<GridAxis, 3>& axes = m.axes;
  auto draw = [&](const std::array<GridAxis, 3>* a) {
    Image img(s.width, s.height);
    draw_box_outline(img, g, s, a);
    return img;
  };
  const Image plain = draw(nullptr), ticked = draw(&axes);
  const std::array<GridAxis, 3> bare{};
  EXPECT_EQ(draw(&bare).rgb, plain.rgb) << "an axis without coordinates gets no ticks";
  EXPECT_NE(ticked.rgb, plain.rgb);
  // Label ink (the labels' grey) near the bottom and the left edges of the box, none elsewhere.
  const CameraFrame frame = orbit_frame(s.camera, g, s.width, s.height);
  const auto sw = *project_to_pixel(frame, g, glm::dvec3(-0.5), s.width, s.height);
  int south = 0, west = 0, elsewhere = 0;
  for (uint32_t y = 0; y < ticked.height; ++y)
    for (uint32_t x = 0; x < ticked.width; ++x) {
      const uint8_t* p = ticked.at(x, y);
      if (!(p[0] == 60 && p[1] == 60 && p[2] == 60)) continue;
      const bool near_south = std::abs(double(y) - sw.y) < 20, near_west = std::abs(double(x) - sw.x) < 30;
      south += near_south;
      west += near_west && !near_south;
      elsewhere += !near_south && !near_west;
    }
  EXPECT_GT(south, 60) << "longitude labels";
  EXPECT_GT(west, 30) << "latitude labels";
  EXPECT_EQ(elsewhere, 0);
  // The same pixels with another text face installed: the labels use the fixed font.
  struct Wide : TextFace {
    int draw(Image&, int, int, const std::string& t, Rgb8, int) const override { return int(t.size()) * 20; }
    int width(const std::string& t, int) const override { return int(t.size()) * 20; }
    int height(int) const override { return 30; }
  } wide;
  set_text_face(&wide);
  const Image with_face = draw(&axes);
  set_text_face(nullptr);
  EXPECT_EQ(with_face.rgb, ticked.rgb);
}

// A marker's dot would cover a tick label ("45N" read "4*N" under the ERA5 recipe's marker at
// lat 45): that label gives way, the others stay. Here the EQ label.
TEST(AxisTicks, ALabelUnderAMarkerGivesWay) {
  const MapView m;
  const VolumeGeometry& g = m.geometry;
  const RenderSettings& s = m.settings;
  const std::array<GridAxis, 3>& axes = m.axes;
  const CameraFrame frame = orbit_frame(s.camera, g, s.width, s.height);
  auto ink = [](const Image& img, int x0, int y0, int x1, int y1) {
    int n = 0;
    for (int y = std::max(0, y0); y < std::min<int>(y1, int(img.height)); ++y)
      for (int x = std::max(0, x0); x < std::min<int>(x1, int(img.width)); ++x) {
        const uint8_t* p = img.at(uint32_t(x), uint32_t(y));
        n += p[0] == 60 && p[1] == 60 && p[2] == 60;
      }
    return n;
  };
  Image plain(s.width, s.height);
  draw_box_outline(plain, g, s, &axes);
  // The EQ label (the one latitude label at this size): ink beside the west edge on the row of
  // latitude 0 (index 18).
  const auto row = *project_to_pixel(frame, g, glm::dvec3(-0.5, 18, -0.5), s.width, s.height);
  int x0 = int(s.width), x1 = -1;
  for (int y = int(row.y) - 4; y <= int(row.y) + 4; ++y)
    for (int x = 0; x < 80; ++x)
      if (ink(plain, x, y, x + 1, y + 1)) x0 = std::min(x0, x), x1 = std::max(x1, x);
  ASSERT_LT(x0, x1) << "no EQ label found";
  // The grid point on the equator whose dot falls on the label's middle.
  uint64_t best = 0;
  double gap = 1e9;
  for (uint64_t i = 0; i < 20; ++i) {
    const auto p = *project_to_pixel(frame, g, glm::dvec3(double(i), 18, 0), s.width, s.height);
    if (std::abs(p.x - 0.5 * (x0 + x1)) < gap) gap = std::abs(p.x - 0.5 * (x0 + x1)), best = i;
  }
  Image marked(s.width, s.height);
  draw_box_outline(marked, g, s, &axes, {GridIndex{best, 18, 0}});
  EXPECT_GT(ink(plain, x0, int(row.y) - 5, x1 + 1, int(row.y) + 6), 10);
  EXPECT_EQ(ink(marked, x0, int(row.y) - 5, x1 + 1, int(row.y) + 6), 0) << "the EQ label is still under the dot";
  // Every other label is where it was.
  const int all = ink(plain, 0, 0, int(s.width), int(s.height)), kept = ink(marked, 0, 0, int(s.width), int(s.height));
  EXPECT_GT(kept, all / 2);
  EXPECT_EQ(all - kept, ink(plain, x0, int(row.y) - 5, x1 + 1, int(row.y) + 6));
}

}  // namespace
}  // namespace tfm
