// Axis-aligned slices: which voxels each picture row and column shows (north and up at the top),
// picture sizes from spacing and vertical exaggeration, colours over the background, no-data grey,
// and errors for planes outside the grid.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "tfmatch/model/slice.h"

namespace tfm {
namespace {

Volume numbered(uint64_t nx, uint64_t ny, uint64_t nz) {
  Volume v;
  v.dims = {nx, ny, nz};
  for (uint64_t z = 0; z < nz; ++z)
    for (uint64_t y = 0; y < ny; ++y)
      for (uint64_t x = 0; x < nx; ++x) v.values.push_back(float(100 * z + 10 * y + x));
  return v;
}

TEST(Slice, RowsRunFromTheTopDownAndColumnsAlongTheLowerAxis) {
  const Volume v = numbered(4, 3, 2);
  const SliceValues z = extract_slice(v, 2, 1);  // x across, y up
  EXPECT_EQ(z.width, 4u);
  EXPECT_EQ(z.height, 3u);
  EXPECT_EQ(z.values.front(), 100 + 20 + 0);  // top-left: highest y (north), x = 0
  EXPECT_EQ(z.values.back(), 100 + 0 + 3);    // bottom-right: y = 0, x = 3
  const SliceValues y = extract_slice(v, 1, 2);  // x across, z up
  EXPECT_EQ(y.width, 4u);
  EXPECT_EQ(y.height, 2u);
  EXPECT_EQ(y.values[0], 100 + 20 + 0);
  EXPECT_EQ(y.values[4 + 3], 0 + 20 + 3);
  const SliceValues x = extract_slice(v, 0, 3);  // y across, z up
  EXPECT_EQ(x.across, 1);
  EXPECT_EQ(x.up, 2);
  EXPECT_EQ(x.width, 3u);
  EXPECT_EQ(x.height, 2u);
  EXPECT_EQ(x.values[0], 100 + 0 + 3);
  EXPECT_EQ(x.values[3 + 2], 0 + 20 + 3);
  EXPECT_THROW(extract_slice(v, 3, 0), std::invalid_argument);
  EXPECT_THROW(extract_slice(v, 2, 2), std::invalid_argument);
}

TEST(Slice, PictureKeepsThePhysicalAspectWithVerticalExaggeration) {
  Volume v = numbered(40, 20, 5);
  v.spacing = {1.0, 1.0, 2.0};
  TransferFunction tf;
  tf.rgba = {{0, 0, 0, 1}, {1, 1, 1, 1}};
  SliceStyle style;
  style.max_size = 200;
  const SliceValues y = extract_slice(v, 1, 0);  // 40 x 5 voxels, 40 x 10 units
  Image img = slice_image(v, y, tf, {0.0, 500.0}, style);
  EXPECT_EQ(img.width, 200u);
  EXPECT_EQ(img.height, 50u);
  style.z_scale = 4.0;  // 40 x 40 units
  img = slice_image(v, y, tf, {0.0, 500.0}, style);
  EXPECT_EQ(img.width, 200u);
  EXPECT_EQ(img.height, 200u);
  // Never less than a pixel per voxel.
  style.max_size = 10;
  style.z_scale = 1.0;
  img = slice_image(v, extract_slice(v, 2, 0), tf, {0.0, 500.0}, style);
  EXPECT_EQ(img.width, 40u);
  EXPECT_EQ(img.height, 20u);
}

// A plane through few levels is not a strip: its shorter side is at least a quarter of the longer
// (two ERA5 levels across 120 longitudes were 4 pixels tall), and each level takes half of it.
// (The labels' collision guard in label_slice_axes is not asserted here.)
TEST(Slice, FewLevelsStillMakeAPictureTallEnoughToRead) {
  Volume v = numbered(120, 61, 2);
  v.spacing = {3.0, 3.0, 1.0};
  TransferFunction tf;
  tf.rgba = {{0, 0, 0, 1}, {1, 1, 1, 1}};
  SliceStyle style;
  style.max_size = 480;
  const SliceValues y = extract_slice(v, 1, 30);  // 120 x 2 voxels, 360 x 2 units
  const Image img = slice_image(v, y, tf, {0.0, 120.0 * 61 * 2}, style);
  EXPECT_EQ(img.width, 480u);
  EXPECT_EQ(img.height, 120u);
  // The two levels split the height evenly: the row above the middle is level 1, below level 0.
  EXPECT_NE(img.at(5, 59)[0], img.at(5, 60)[0]);
  EXPECT_EQ(img.at(5, 0)[0], img.at(5, 59)[0]);
  const Image labelled = label_slice_axes(img, v, y);
  EXPECT_GT(labelled.height, img.height);
}

TEST(Slice, ColoursAreTheTfsAtFullStrengthOrOverTheBackgroundByOpacity) {
  Volume v;
  v.dims = {2, 2, 1};
  v.values = {0.0f, 1.0f, NAN, 0.5f};  // rows from the top: (y=1) NaN, 0.5 ; (y=0) 0, 1
  TransferFunction tf;
  tf.rgba = {{0.0, 0.0, 0.0, 0.25}, {1.0, 0.0, 0.0, 0.5}};
  SliceStyle style;
  style.background = {1.0, 1.0, 1.0};
  style.max_size = 2;
  // By default the TF's colour whatever its opacity: low opacities do not fade to white.
  const Image full = slice_image(v, extract_slice(v, 2, 0), tf, {0.0, 1.0}, style);
  ASSERT_EQ(full.width, 2u);
  auto full_px = [&](uint32_t x, uint32_t y) { return Rgb8{full.at(x, y)[0], full.at(x, y)[1], full.at(x, y)[2]}; };
  EXPECT_EQ(full_px(0, 0), srgb8(0.55, 0.55, 0.55));
  EXPECT_EQ(full_px(1, 1), srgb8(1.0, 0.0, 0.0));
  EXPECT_EQ(full_px(0, 1), srgb8(0.0, 0.0, 0.0));
  EXPECT_EQ(full_px(1, 0), srgb8(0.5, 0.0, 0.0));

  style.shading = SliceShading::Opacity;
  style.opacity_scale = max_opacity(tf);  // 0.5: the most opaque entry shows opaque
  const Image img = slice_image(v, extract_slice(v, 2, 0), tf, {0.0, 1.0}, style);
  ASSERT_EQ(img.width, 2u);
  auto px = [&](uint32_t x, uint32_t y) { return Rgb8{img.at(x, y)[0], img.at(x, y)[1], img.at(x, y)[2]}; };
  EXPECT_EQ(px(0, 0), srgb8(0.55, 0.55, 0.55));  // NaN: no data (its checkerboard's first square)
  EXPECT_EQ(px(1, 1), srgb8(1.0, 0.0, 0.0));     // value 1: red at full (scaled) opacity
  EXPECT_EQ(px(0, 1), srgb8(0.5, 0.5, 0.5));     // value 0: black at half opacity over white
  EXPECT_EQ(px(1, 0), srgb8(0.5 * 0.75 + 0.25, 0.25, 0.25));  // 0.5: (0.5,0,0) at 0.75 over white
}

// No data is a checkerboard of two greys in 4-pixel squares (a plain grey read as a grey TF's
// values); a grey TF's colour is one grey whichever pixel.
TEST(Slice, NoDataIsACheckerboardNoTfMakes) {
  Volume v;
  v.dims = {2, 1, 1};
  v.values = {NAN, 0.5f};
  TransferFunction grey;
  grey.rgba = {{0.55, 0.55, 0.55, 1.0}, {0.55, 0.55, 0.55, 1.0}};
  SliceStyle style;
  style.max_size = 16;  // the x-z plane of 2 x 1 voxels: 8 x 8 pixels a voxel, the NaN one on the left
  const SliceValues sv = extract_slice(v, 1, 0);
  const Image img = slice_image(v, sv, grey, {0.0, 1.0}, style);
  ASSERT_EQ(img.width, 16u);
  ASSERT_EQ(img.height, 8u);
  auto px = [&](uint32_t x, uint32_t y) { return Rgb8{img.at(x, y)[0], img.at(x, y)[1], img.at(x, y)[2]}; };
  const Rgb8 light = srgb8(0.55, 0.55, 0.55), dark = srgb8(0.25, 0.25, 0.25);
  // Four squares of 4 x 4 pixels, alternating: light, dark across the top, dark, light below.
  EXPECT_EQ(px(0, 0), light);
  EXPECT_EQ(px(4, 0), dark);
  EXPECT_EQ(px(0, 4), dark);
  EXPECT_EQ(px(7, 7), light);
  for (uint32_t y = 0; y < img.height; ++y)
    for (uint32_t x = 8; x < 16; ++x) ASSERT_EQ(px(x, y), light) << x << " " << y;  // the grey TF: one grey
}

// The slice point is crossed and markers dotted where they lie in the plane; points off the plane
// leave the picture as it was.
TEST(Slice, MarksTheSlicePointAndMarkersInThePlane) {
  const Volume v = numbered(20, 10, 3);
  TransferFunction blue;
  blue.rgba = {{0.0, 0.0, 1.0, 1.0}, {0.0, 0.0, 1.0, 1.0}};
  SliceStyle style;
  style.max_size = 200;  // 10 pixels a voxel
  const SliceValues z1 = extract_slice(v, 2, 1);
  const Image plain = slice_image(v, z1, blue, {0.0, 300.0}, style);
  Image marked = plain;
  mark_slice(marked, z1, {{5, 2, 1}}, {{15, 7, 1}, {3, 3, 0}});
  auto px = [&](const Image& img, int x, int y) { return Rgb8{img.at(x, y)[0], img.at(x, y)[1], img.at(x, y)[2]}; };
  // Voxel (5, 2): column 5, row 10 - 1 - 2 = 7; its centre (55, 75). The cross's arms are black.
  EXPECT_EQ(px(marked, 55 + 5, 75), (Rgb8{0, 0, 0}));
  EXPECT_EQ(px(marked, 55, 75 - 5), (Rgb8{0, 0, 0}));
  EXPECT_EQ(px(marked, 55, 75), px(plain, 55, 75));  // the voxel itself stays visible
  // Marker (15, 7, 1): red at the centre of column 15, row 2.
  const Rgb8 dot = px(marked, 155, 25);
  EXPECT_GT(dot[0], 200);
  EXPECT_LT(dot[2], 80);
  // Marker (3, 3, 0) is in plane z = 0: nothing drawn at (35, 65) in z = 1.
  EXPECT_EQ(px(marked, 35, 65), px(plain, 35, 65));
  size_t changed = 0;
  for (uint32_t y = 0; y < plain.height; ++y)
    for (uint32_t x = 0; x < plain.width; ++x) changed += !(px(marked, int(x), int(y)) == px(plain, int(x), int(y)));
  EXPECT_LT(changed, 400u);  // a cross and a dot, not more
}

// The axes drawn around a slice: the picture itself unchanged inside margins, the coordinates
// and names of both axes in ink beside and below it.
TEST(Slice, LabelledAxesFrameThePictureUnchanged) {
  Volume v = numbered(30, 12, 2);
  v.axes[0] = {"lon", "degrees_east", {}};
  v.axes[1] = {"lat", "degrees_north", {}};
  v.spacing = {3.0, 3.0, 1.0};
  v.origin = {0.0, -90.0, 0.0};
  TransferFunction tf;
  tf.rgba = {{0, 0, 1, 1}, {1, 0, 0, 1}};
  SliceStyle style;
  style.max_size = 120;
  const SliceValues z = extract_slice(v, 2, 0);
  const Image picture = slice_image(v, z, tf, {0.0, 1000.0}, style);
  const Image labelled = label_slice_axes(picture, v, z);
  ASSERT_GT(labelled.width, picture.width + 10);
  ASSERT_GT(labelled.height, picture.height + 2 * uint32_t(text_height()));
  // Find the picture inside: its top-left pixel's colour runs on for its width.
  bool found = false;
  for (uint32_t oy = 0; oy + picture.height <= labelled.height && !found; ++oy)
    for (uint32_t ox = 0; ox + picture.width <= labelled.width && !found; ++ox) {
      bool same = true;
      for (uint32_t y = 0; y < picture.height && same; y += 7)
        for (uint32_t x = 0; x < picture.width && same; x += 5)
          same = std::equal(picture.at(x, y), picture.at(x, y) + 3, labelled.at(ox + x, oy + y));
      if (!same) continue;
      found = true;
      // Something is written below and left of it (the axes' numbers and names).
      int ink_below = 0, ink_left = 0;
      for (uint32_t y = oy + picture.height + 2; y < labelled.height; ++y)
        for (uint32_t x = 0; x < labelled.width; ++x) ink_below += labelled.at(x, y)[0] < 160;
      for (uint32_t y = 0; y < labelled.height; ++y)
        for (uint32_t x = 0; x + 2 < ox; ++x) ink_left += labelled.at(x, y)[0] < 160;
      EXPECT_GT(ink_below, 40);
      EXPECT_GT(ink_left, 20);
    }
  EXPECT_TRUE(found);
  EXPECT_EQ(axis_label(v, 0), "lon (degrees_east)");
  EXPECT_EQ(axis_label(v, 2), "z");
}

TEST(Slice, DescribesThePlaneWithItsCoordinate) {
  Volume v = numbered(2, 2, 3);
  EXPECT_EQ(describe_slice(v, 2, 1), "z = 1");
  v.axes[2].name = "level";
  v.axes[2].units = "hPa";
  v.axes[2].coordinates = {1000, 850, 500};
  EXPECT_EQ(describe_slice(v, 2, 2), "z = 2 (level 500 hPa)");
}

}  // namespace
}  // namespace tfm
