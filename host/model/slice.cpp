// Axis-aligned slices as pictures.
#include "tfmatch/model/slice.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace tfm {

SliceValues extract_slice(const Volume& v, int axis, uint64_t index) {
  if (axis < 0 || axis > 2) throw std::invalid_argument("slice: axis " + std::to_string(axis) + " (need 0, 1 or 2)");
  if (index >= v.dims[size_t(axis)])
    throw std::invalid_argument("slice: index " + std::to_string(index) + " outside axis " + std::to_string(axis) +
                                " of " + std::to_string(v.dims[size_t(axis)]));
  SliceValues s;
  s.axis = axis;
  s.index = index;
  s.across = axis == 0 ? 1 : 0;
  s.up = axis == 2 ? 1 : 2;
  s.width = v.dims[size_t(s.across)];
  s.height = v.dims[size_t(s.up)];
  s.values.resize(s.width * s.height);
  std::array<uint64_t, 3> p{};
  p[size_t(axis)] = index;
  for (uint64_t r = 0; r < s.height; ++r) {
    p[size_t(s.up)] = s.height - 1 - r;  // top row: the highest index (north, up)
    for (uint64_t c = 0; c < s.width; ++c) {
      p[size_t(s.across)] = c;
      s.values[r * s.width + c] = v.at(p[0], p[1], p[2]);
    }
  }
  return s;
}

double max_opacity(const TransferFunction& tf) {
  double m = 1e-6;
  for (const Rgba& e : tf.rgba) m = std::max(m, e[3]);
  return m;
}

Image slice_image(const Volume& v, const SliceValues& s, const TransferFunction& tf, const FieldRange& range,
                  const SliceStyle& style) {
  // Physical size of a voxel in the picture; the longer side scaled to max_size pixels (but at
  // least one pixel per voxel).
  auto extent = [&](int a) { return v.spacing[size_t(a)] * (a == 2 ? style.z_scale : 1.0); };
  const double w_phys = double(s.width) * extent(s.across), h_phys = double(s.height) * extent(s.up);
  const double px_per_unit = double(style.max_size) / std::max(w_phys, h_phys);
  double cell_w = std::max(1.0, extent(s.across) * px_per_unit), cell_h = std::max(1.0, extent(s.up) * px_per_unit);
  // The shorter side at least a quarter of the longer: a plane through two pressure levels of a
  // 120-wide grid was a strip 4 pixels tall, its tick labels printed over each other.
  const double min_side = double(style.max_size) / 4.0;
  cell_w = std::max(cell_w, min_side / double(s.width));
  cell_h = std::max(cell_h, min_side / double(s.height));
  Image img(uint32_t(std::max(1.0, std::round(cell_w * double(s.width)))),
            uint32_t(std::max(1.0, std::round(cell_h * double(s.height)))));
  const FieldMapping m = make_mapping(range, uint32_t(tf.size()));
  std::vector<Rgb8> colour(s.values.size());
  std::vector<uint8_t> no_data(s.values.size(), 0);
  for (size_t i = 0; i < s.values.size(); ++i) {
    uint32_t j;
    float w;
    if (!tf_coordinate(s.values[i], m, j, w)) {
      no_data[i] = 1;
      continue;
    }
    Rgba c;
    for (int k = 0; k < 4; ++k) c[k] = std::clamp((1.0 - w) * tf.rgba[j][k] + double(w) * tf.rgba[j + 1][k], 0.0, 1.0);
    const double a = style.shading == SliceShading::Colour ? 1.0 : std::min(1.0, c[3] / style.opacity_scale);
    colour[i] = srgb8(a * c[0] + (1 - a) * style.background[0], a * c[1] + (1 - a) * style.background[1],
                      a * c[2] + (1 - a) * style.background[2]);
  }
  const Rgb8 grey = srgb8(style.no_data[0], style.no_data[1], style.no_data[2]);
  const Rgb8 alt = srgb8(style.no_data_alt[0], style.no_data_alt[1], style.no_data_alt[2]);
  for (uint32_t y = 0; y < img.height; ++y) {
    const uint64_t r = std::min<uint64_t>(s.height - 1, uint64_t(double(y) / double(img.height) * double(s.height)));
    for (uint32_t x = 0; x < img.width; ++x) {
      const uint64_t c = std::min<uint64_t>(s.width - 1, uint64_t(double(x) / double(img.width) * double(s.width)));
      const size_t i = r * s.width + c;
      img.set(int(x), int(y), no_data[i] ? ((x / 4 + y / 4) % 2 ? alt : grey) : colour[i]);
    }
  }
  return img;
}

void mark_slice(Image& picture, const SliceValues& s, const std::vector<GridIndex>& crosses,
                const std::vector<GridIndex>& dots) {
  const double cell_w = double(picture.width) / double(s.width), cell_h = double(picture.height) / double(s.height);
  // The centre of the point's voxel in the picture, if the point is in the plane.
  auto centre = [&](const GridIndex& p) -> std::optional<std::array<double, 2>> {
    if (p[size_t(s.axis)] != s.index || p[size_t(s.across)] >= s.width || p[size_t(s.up)] >= s.height) return std::nullopt;
    const double row = double(s.height - 1 - p[size_t(s.up)]);  // the top row is the highest index
    // On a pixel's centre, so that one-pixel lines are crisp.
    return std::array<double, 2>{std::floor((double(p[size_t(s.across)]) + 0.5) * cell_w) + 0.5,
                                 std::floor((row + 0.5) * cell_h) + 0.5};
  };
  const double arm = std::max(6.0, 0.04 * std::min(picture.width, picture.height));
  for (const GridIndex& p : crosses)
    if (const auto c = centre(p)) {
      const auto [x, y] = *c;
      for (const auto& [colour, width] : {std::pair{Rgb8{255, 255, 255}, 3.0}, std::pair{Rgb8{0, 0, 0}, 1.0}}) {
        draw_line(picture, x - arm, y, x - 2, y, colour, width);
        draw_line(picture, x + 2, y, x + arm, y, colour, width);
        draw_line(picture, x, y - arm, x, y - 2, colour, width);
        draw_line(picture, x, y + 2, x, y + arm, colour, width);
      }
    }
  const double radius = std::max(2.5, 0.012 * std::min(picture.width, picture.height));
  for (const GridIndex& p : dots)
    if (const auto c = centre(p)) draw_dot(picture, (*c)[0], (*c)[1], radius, {220, 20, 20}, {255, 255, 255});
}

std::string axis_label(const Volume& v, int axis) {
  static const char* names[3] = {"x", "y", "z"};
  const GridAxis& a = v.axes[size_t(axis)];
  std::string label = a.name.empty() ? names[axis] : a.name;
  if (!a.units.empty()) label += " (" + a.units + ")";
  return label;
}

namespace {
std::string coordinate_text(const Volume& v, int axis, uint64_t i) {
  std::ostringstream os;
  os << axis_coordinate(v, axis, i);
  return os.str();
}
}  // namespace

Image label_slice_axes(const Image& picture, const Volume& v, const SliceValues& s) {
  const Rgb8 ink{60, 60, 60}, tick{150, 150, 150};
  const int line = text_height(1), pad = 4;
  const std::string up_first = coordinate_text(v, s.up, 0), up_last = coordinate_text(v, s.up, s.height - 1);
  const std::string up_name = axis_label(v, s.up);
  // The vertical axis's values sit left of the picture, its name above them.
  const int left = pad + std::max({text_width(up_first), text_width(up_last)}) + pad + 3;
  const int top = line + line / 2 + pad + 2;  // room for the name above the top value
  const int bottom = 3 + pad + 2 * line + pad;
  const int right = pad + text_width(coordinate_text(v, s.across, s.width - 1)) / 2;
  Image out(uint32_t(left + int(picture.width) + right), uint32_t(top + int(picture.height) + bottom));
  blit(out, picture, left, top);
  const int x0 = left, x1 = left + int(picture.width) - 1, y0 = top, y1 = top + int(picture.height) - 1;
  // Ticks at the first and last voxel's centre (each voxel is a cell of equal size).
  const double cell_w = double(picture.width) / double(s.width), cell_h = double(picture.height) / double(s.height);
  const double first_x = x0 + 0.5 * cell_w, last_x = x1 + 1 - 0.5 * cell_w;
  const double top_y = y0 + 0.5 * cell_h, bottom_y = y1 + 1 - 0.5 * cell_h;
  draw_line(out, first_x, y1 + 1, first_x, y1 + 4, tick);
  draw_line(out, last_x, y1 + 1, last_x, y1 + 4, tick);
  draw_line(out, x0 - 4, top_y, x0 - 1, top_y, tick);
  draw_line(out, x0 - 4, bottom_y, x0 - 1, bottom_y, tick);
  const std::string across_first = coordinate_text(v, s.across, 0), across_last = coordinate_text(v, s.across, s.width - 1);
  const int ty = y1 + 4 + pad / 2;
  const int first_left = std::max(0, int(first_x) - text_width(across_first) / 2);
  draw_text(out, first_left, ty, across_first, ink);
  if (int(last_x) - text_width(across_last) / 2 > first_left + text_width(across_first) + 4)
    draw_text(out, int(last_x) - text_width(across_last) / 2, ty, across_last, ink);
  const std::string across_name = axis_label(v, s.across);
  draw_text(out, x0 + (int(picture.width) - text_width(across_name)) / 2, ty + line, across_name, ink);
  draw_text(out, x0 - 4 - pad - text_width(up_last), int(top_y) - line / 2, up_last, ink);
  if (bottom_y - top_y >= line + 2)  // else the two labels would print over each other
    draw_text(out, x0 - 4 - pad - text_width(up_first), int(bottom_y) - line / 2, up_first, ink);
  draw_text(out, std::max(0, x0 - text_width(up_name) / 2), 1, up_name, ink);
  return out;
}

std::string describe_slice(const Volume& v, int axis, uint64_t index) {
  static const char* names[3] = {"x", "y", "z"};
  std::ostringstream os;
  os << names[axis] << " = " << index;
  const GridAxis& a = v.axes[size_t(axis)];
  if (!a.name.empty()) {
    os << " (" << a.name << " " << axis_coordinate(v, axis, index);
    if (!a.units.empty()) os << " " << a.units;
    os << ")";
  }
  return os.str();
}

}  // namespace tfm
