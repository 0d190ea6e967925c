// Axis-aligned slices as pictures.
#include "slice.h"

#include <algorithm>
#include <cmath>
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
  const double cell_w = std::max(1.0, extent(s.across) * px_per_unit), cell_h = std::max(1.0, extent(s.up) * px_per_unit);
  Image img(uint32_t(std::max(1.0, std::round(cell_w * double(s.width)))),
            uint32_t(std::max(1.0, std::round(cell_h * double(s.height)))));
  const FieldMapping m = make_mapping(range, uint32_t(tf.size()));
  std::vector<Rgb8> colour(s.values.size());
  for (size_t i = 0; i < s.values.size(); ++i) {
    uint32_t j;
    float w;
    if (!tf_coordinate(s.values[i], m, j, w)) {
      colour[i] = srgb8(style.no_data[0], style.no_data[1], style.no_data[2]);
      continue;
    }
    Rgba c;
    for (int k = 0; k < 4; ++k) c[k] = std::clamp((1.0 - w) * tf.rgba[j][k] + double(w) * tf.rgba[j + 1][k], 0.0, 1.0);
    const double a = std::min(1.0, c[3] / style.opacity_scale);
    colour[i] = srgb8(a * c[0] + (1 - a) * style.background[0], a * c[1] + (1 - a) * style.background[1],
                      a * c[2] + (1 - a) * style.background[2]);
  }
  for (uint32_t y = 0; y < img.height; ++y) {
    const uint64_t r = std::min<uint64_t>(s.height - 1, uint64_t(double(y) / double(img.height) * double(s.height)));
    for (uint32_t x = 0; x < img.width; ++x) {
      const uint64_t c = std::min<uint64_t>(s.width - 1, uint64_t(double(x) / double(img.width) * double(s.width)));
      img.set(int(x), int(y), colour[r * s.width + c]);
    }
  }
  return img;
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
