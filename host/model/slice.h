// Axis-aligned slices of a volume as pictures: the plane through one index of an axis, classified
// by a TF and shown the way a map is read: x east to the right, y north up, z up (DESIGN.md's
// world orientation), each voxel a rectangle of its physical aspect (spacing, vertical
// exaggeration), nearest-neighbour so every voxel stays visible as one value.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// The plane `index` of `axis` (0 x, 1 y, 2 z): its horizontal axis is the lower of the other two
// (x for y and z slices, y for x slices), its vertical axis the higher. Values row-major from the
// top row (highest index of the vertical axis) down.
struct SliceValues {
  int axis = 2;
  uint64_t index = 0;
  int across = 0, up = 1;      // the picture's horizontal and vertical volume axes
  uint64_t width = 0, height = 0;
  std::vector<float> values;
};
// Throws std::invalid_argument for an axis outside 0..2 or an index outside the grid.
SliceValues extract_slice(const Volume& v, int axis, uint64_t index);

// How a slice shows a voxel: the TF's colour at full strength (Colour: what the value is, even
// where the TF makes it nearly transparent), or that colour over the background by its opacity
// (Opacity: what a rendering lets through; low opacities fade to the background).
enum class SliceShading { Colour, Opacity };

struct SliceStyle {
  std::array<double, 3> background{1.0, 1.0, 1.0};  // linear RGB (as RenderSettings::background)
  // NaN voxels: a checkerboard of these two greys (linear RGB) in squares of 4 pixels, a pattern
  // no TF colour makes (a plain grey was taken for a grey TF's values).
  std::array<double, 3> no_data{0.55, 0.55, 0.55};
  std::array<double, 3> no_data_alt{0.25, 0.25, 0.25};
  SliceShading shading = SliceShading::Colour;
  // Opacity shading: a slice shows one sample per pixel rather than an integral along a ray, so
  // the TF's opacity is rescaled: alpha / opacity_scale (clamped to 1) over the background. Pass
  // the largest opacity of the TF the picture is compared with, so fully opaque means "as opaque
  // as it gets".
  double opacity_scale = 1.0;
  double z_scale = 1.0;       // vertical exaggeration of z (RenderSettings::z_scale)
  // Longer side of the picture, pixels (at least one per voxel); the shorter side is at least a
  // quarter of it, whatever the plane's aspect (a slice through few levels is not a thin strip).
  uint32_t max_size = 384;
};

// T(v) of every voxel of the slice as style.shading says (linear RGB), sRGB-encoded.
Image slice_image(const Volume& v, const SliceValues& slice, const TransferFunction& tf, const FieldRange& range,
                  const SliceStyle& style);

// Marks points of the grid on `picture` (slice_image of `slice`, before label_slice_axes) where
// they lie in the slice's plane: a black-and-white cross at each of `crosses` (the point the
// slices go through), a red dot ringed in white at each of `dots` (the renderings' markers).
void mark_slice(Image& picture, const SliceValues& slice, const std::vector<GridIndex>& crosses,
                const std::vector<GridIndex>& dots);

// The largest opacity of a TF (at least 1e-6), for SliceStyle::opacity_scale.
double max_opacity(const TransferFunction& tf);

// `picture` (slice_image of `slice`) with its axes labelled in margins: below, the horizontal
// axis's name, units and first and last coordinates; at the left, the vertical axis's (the top
// row is its last index).
Image label_slice_axes(const Image& picture, const Volume& v, const SliceValues& slice);

// "lon (degrees_east)" or "x": an axis as a label names it.
std::string axis_label(const Volume& v, int axis);

// "z = 12 (level 500 hPa)"-style description of a slice for captions.
std::string describe_slice(const Volume& v, int axis, uint64_t index);

}  // namespace tfm
