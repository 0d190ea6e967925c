// Orbit camera frames, marching constants and double-precision ray setup.
#include "tfmatch/model/camera.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "tfmatch/model/axis_ticks.h"
#include "tfmatch/shaders/render_layout.h"  // TFM_MAX_SAMPLE_OPTICAL_DEPTH, the shaders' clamp

namespace tfm {

static_assert(kMaxSampleOpticalDepth == TFM_MAX_SAMPLE_OPTICAL_DEPTH, "CPU and GPU clamp the same depth");

VolumeGeometry VolumeGeometry::from(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing,
                                    double z_scale) {
  for (int a = 0; a < 3; ++a) {
    if (dims[a] == 0) throw std::runtime_error("volume geometry: empty grid");
    if (!(spacing[a] > 0) || !std::isfinite(spacing[a]))
      throw std::runtime_error("volume geometry: spacing must be positive and finite");
  }
  if (!(z_scale > 0) || !std::isfinite(z_scale)) throw std::runtime_error("volume geometry: z scale must be positive");
  const glm::dvec3 physical(spacing[0], spacing[1], spacing[2] * z_scale);
  const double finest = std::min({physical.x, physical.y, physical.z});
  VolumeGeometry g;
  g.dims = dims;
  g.axis_scale = physical / finest;
  return g;
}

namespace {
glm::dvec3 as_vector(const std::array<uint64_t, 3>& d) { return {double(d[0]), double(d[1]), double(d[2])}; }
}  // namespace

glm::dvec3 VolumeGeometry::center() const { return (as_vector(dims) - 1.0) * 0.5 * axis_scale; }

glm::dvec3 VolumeGeometry::half_extent() const { return as_vector(dims) * 0.5 * axis_scale; }

double VolumeGeometry::radius() const { return glm::length(half_extent()); }

double VolumeGeometry::box_length() const {
  glm::dvec3 h = half_extent();
  return 2.0 * std::max({h.x, h.y, h.z});
}

CameraFrame orbit_frame(const OrbitCamera& camera, const VolumeGeometry& geometry, uint32_t width, uint32_t height) {
  const double deg = std::numbers::pi / 180.0;
  const double az = camera.azimuth_deg * deg, el = camera.elevation_deg * deg;
  const double ca = std::cos(az), sa = std::sin(az), ce = std::cos(el), se = std::sin(el);
  CameraFrame f;
  const glm::dvec3 outward(ce * ca, ce * sa, se);  // box centre -> eye
  f.forward = -outward;
  // d(outward)/d(azimuth) / cos(el) and d(outward)/d(elevation): unit length and orthogonal to
  // the view direction for every elevation, so nothing degenerates at +-90 degrees.
  f.right = glm::dvec3(-sa, ca, 0.0);
  f.up = glm::dvec3(-se * ca, -se * sa, ce);
  f.tan_half_fov = std::tan(0.5 * camera.fov_deg * deg);
  f.aspect = double(width) / double(height);
  double distance = camera.distance * geometry.radius();
  if (camera.distance == 0) {
    // A corner c (relative to the centre) lies at depth D - c.outward in front of the eye, at
    // c.right and c.up across: D must make both ratios fit the half-angles (with a margin), and
    // keep every corner in front of the eye.
    const double margin = 0.94, tx = f.tan_half_fov * f.aspect * margin, ty = f.tan_half_fov * margin;
    const glm::dvec3 h = geometry.half_extent();
    distance = 0.0;
    for (int corner = 0; corner < 8; ++corner) {
      const glm::dvec3 c((corner & 1 ? 1 : -1) * h.x, (corner & 2 ? 1 : -1) * h.y, (corner & 4 ? 1 : -1) * h.z);
      const double along = glm::dot(c, outward);
      distance = std::max({distance, along + std::abs(glm::dot(c, f.right)) / tx, along + std::abs(glm::dot(c, f.up)) / ty,
                           along + 0.05 * geometry.radius()});
    }
  }
  f.eye = geometry.center() + distance * outward;
  return f;
}

std::optional<glm::dvec2> project_to_pixel(const CameraFrame& f, const VolumeGeometry& g, const glm::dvec3& index_point,
                                           uint32_t width, uint32_t height) {
  const glm::dvec3 d = index_point * g.axis_scale - f.eye;
  const double depth = glm::dot(d, f.forward);
  if (!(depth > 0.0)) return std::nullopt;
  // pixel_ray: sx = (2 (px + 0.5) / width - 1) tan aspect, sy = (1 - 2 (py + 0.5) / height) tan.
  const double sx = glm::dot(d, f.right) / depth, sy = glm::dot(d, f.up) / depth;
  const double px = 0.5 * width * (sx / (f.tan_half_fov * f.aspect) + 1.0) - 0.5;
  const double py = 0.5 * height * (1.0 - sy / f.tan_half_fov) - 0.5;
  return glm::dvec2(px, py);
}

MarchConstants march_constants(const RenderSettings& s, const VolumeGeometry& g) {
  validate(s);
  MarchConstants m;
  m.dt = s.step_voxels;
  m.depth_per_alpha = s.opacity_scale * m.dt / g.box_length();
  m.stop_transmittance = 1.0 - s.termination_opacity;
  const double diagonal = 2.0 * g.radius();
  const double steps = std::ceil(diagonal / m.dt) + 2.0;
  if (steps > 1e8) {
    // Mostly a grid whose axes' spacings differ by orders of magnitude (a file's spacing or
    // coordinates in other units than each other): say which, since --step cannot help there.
    const glm::dvec3 extent = 2.0 * g.half_extent();
    std::ostringstream os;
    os << "render settings: rays would take over 10^8 samples: the box is " << extent.x << " x " << extent.y << " x "
       << extent.z << " steps of its finest spacing (grid " << g.dims[0] << "x" << g.dims[1] << "x" << g.dims[2]
       << ", each axis's spacing " << g.axis_scale.x << ", " << g.axis_scale.y << ", " << g.axis_scale.z
       << " times the finest), marched every " << m.dt
       << " of them; check the file's spacing or coordinates (--z-scale scales the vertical one)";
    throw std::runtime_error(os.str());
  }
  m.max_steps = static_cast<uint32_t>(steps);
  return m;
}

RaySegment pixel_ray(const CameraFrame& f, const VolumeGeometry& g, const MarchConstants& m, uint32_t px,
                     uint32_t py, uint32_t width, uint32_t height, double tolerance) {
  const double sx = ((2.0 * (px + 0.5)) / width - 1.0) * f.tan_half_fov * f.aspect;
  const double sy = (1.0 - (2.0 * (py + 0.5)) / height) * f.tan_half_fov;
  const glm::dvec3 dir_world = glm::normalize(f.forward + sx * f.right + sy * f.up);
  const glm::dvec3 o = f.eye / g.axis_scale;
  const glm::dvec3 d = dir_world / g.axis_scale;
  double t0 = 0.0, t1 = 3.0e38;
  for (int a = 0; a < 3; ++a) {
    const double hi = double(g.dims[a]) - 0.5;
    if (std::abs(d[a]) < 1e-30) {
      if (o[a] < -0.5 || o[a] > hi) t1 = -1.0;
    } else {
      const double ta = (-0.5 - o[a]) / d[a], tb = (hi - o[a]) / d[a];
      t0 = std::max(t0, std::min(ta, tb));
      t1 = std::min(t1, std::max(ta, tb));
    }
  }
  RaySegment r;
  r.entry = o + t0 * d;
  r.dir = d;
  r.t_entry = t0;
  r.t_exit = t1;
  if (!(t1 > t0)) return r;
  const double q = (t1 - t0) / m.dt;
  const double count = std::floor(q + 0.5);
  r.steps = static_cast<uint32_t>(std::min(count, double(m.max_steps)));
  r.steps_ambiguous = std::abs(q - std::floor(q) - 0.5) < tolerance;
  if (count >= 1.0 && count <= double(m.max_steps))  // as setup_ray() of shaders/raymarch.glsl
    r.depth_scale = (t1 - t0) / (count * m.dt);
  return r;
}

namespace {

// "x", "y" or "z" (axis 0, 1, 2) as strokes in a 6 x 8 pixel box centred at (cx, cy): the same
// pixels whatever text face a program has installed, so a picture is the same from every command.
void draw_axis_letter(Image& image, int axis, double cx, double cy, Rgb8 c) {
  const double l = cx - 3, r = cx + 3, t = cy - 4, b = cy + 4;
  switch (axis) {
    case 0:
      draw_line(image, l, t, r, b, c, 1.2);
      draw_line(image, r, t, l, b, c, 1.2);
      break;
    case 1:
      draw_line(image, l, t, cx, cy, c, 1.2);
      draw_line(image, r, t, l + 1, b, c, 1.2);
      break;
    default:
      draw_line(image, l, t, r, t, c, 1.2);
      draw_line(image, r, t, l, b, c, 1.2);
      draw_line(image, l, b, r, b, c, 1.2);
      break;
  }
}

// Ticks along the axis edge of axis k (from `origin`, the first voxel's corner, to `end`), at round
// values of its coordinates, each labelled: outside the box (away from its centre in the picture)
// where the picture has room, else just inside the edge on a white patch (a framed box fills the
// picture: a map's edges are the picture's). A label that would touch the previous one, or that a
// marker's dot (`dots`, of `dot_radius`) would cover, is left out.
void draw_coordinate_ticks(Image& image, const CameraFrame& frame, const VolumeGeometry& g, const GridAxis& axis,
                           int k, const glm::dvec2& origin, const glm::dvec2& end, const glm::dvec2& centre,
                           Rgb8 colour, const std::vector<glm::dvec2>& dots, double dot_radius) {
  const glm::dvec2 along = end - origin;
  const double length = glm::length(along);
  const auto& c = axis.coordinates;
  if (length < 80.0 || c.size() != g.dims[size_t(k)] || c.size() < 2) return;
  glm::dvec2 outward(-along.y / length, along.x / length);
  if (glm::dot(outward, 0.5 * (origin + end) - centre) < 0) outward = -outward;
  const Rgb8 text{60, 60, 60}, patch{255, 255, 255};
  const int label_h = 7;
  struct Tick {
    glm::dvec2 at;
    std::string label;
    int width;
  };
  std::vector<Tick> ticks;
  const auto [lo, hi] = std::minmax_element(c.begin(), c.end());
  for (double v : axis_ticks(axis, *lo, *hi, std::max(2, int(length / 70.0)))) {
    const std::optional<double> f = coordinate_index(axis, v);
    if (!f) continue;
    glm::dvec3 point(-0.5);
    point[k] = *f;
    const auto p = project_to_pixel(frame, g, point, image.width, image.height);
    // Not at the edge's ends: the corners belong to two axes, whose labels would meet there.
    if (!p || glm::length(*p - origin) < 12.0 || glm::length(*p - end) < 12.0) continue;
    const std::string label = coordinate_label(axis, v);
    ticks.push_back({*p + 0.5, label, fixed_text_width(label)});
  }
  // A label's top-left corner on side `n`: its centre beyond a 4-pixel tick by its half-extent along n.
  auto label_at = [&](const Tick& t, const glm::dvec2& n) {
    const double reach = 7.0 + 0.5 * (std::abs(n.x) * t.width + std::abs(n.y) * label_h);
    return glm::ivec2(int(std::lround(t.at.x + reach * n.x - 0.5 * t.width)),
                      int(std::lround(t.at.y + reach * n.y - 0.5 * label_h)));
  };
  auto fits = [&](const Tick& t, const glm::ivec2& at) {
    return at.x >= 2 && at.y >= 2 && at.x + t.width + 2 <= int(image.width) && at.y + label_h + 2 <= int(image.height);
  };
  // One side for the whole axis: outside where every label fits there.
  const bool out = std::all_of(ticks.begin(), ticks.end(), [&](const Tick& t) { return fits(t, label_at(t, outward)); });
  const glm::dvec2 n = out ? outward : -outward;
  bool placed = false;
  glm::dvec4 last(0.0);  // the previous label's box: x0, y0, x1, y1
  for (const Tick& t : ticks) {
    const glm::ivec2 at = label_at(t, n);
    if (!fits(t, at)) continue;
    const glm::dvec4 box(at.x - 2, at.y - 2, at.x + t.width + 2, at.y + label_h + 2);
    if (placed && box.x < last.z + 2 && last.x < box.z + 2 && box.y < last.w + 2 && last.y < box.w + 2) continue;
    // A marker's dot drawn over a label turned "45N" into "4*N": the label gives way to the dot.
    const bool under_dot = std::any_of(dots.begin(), dots.end(), [&](const glm::dvec2& d) {
      const glm::dvec2 nearest = glm::clamp(d, glm::dvec2(box.x, box.y), glm::dvec2(box.z, box.w));
      return glm::length(d - nearest) < dot_radius + 1.0;
    });
    if (under_dot) continue;
    draw_line(image, t.at.x, t.at.y, t.at.x + 4.0 * n.x, t.at.y + 4.0 * n.y, colour, 1.0);
    if (!out) fill_rect(image, at.x - 1, at.y - 1, t.width + 2, label_h + 2, patch);
    draw_fixed_text(image, at.x, at.y, t.label, text);
    last = box;
    placed = true;
  }
}

}  // namespace

double marker_radius(uint32_t width, uint32_t height) {
  return std::max(2.5, 0.012 * std::min(width, height));  // about 1 % of the short side, at least 2.5 px
}

void draw_box_outline(Image& image, const VolumeGeometry& g, const RenderSettings& s,
                      const std::array<GridAxis, 3>* axes, const std::vector<GridIndex>& markers) {
  if (!s.box_outline) return;
  const CameraFrame frame = orbit_frame(s.camera, g, image.width, image.height);
  const glm::dvec3 lo(-0.5), hi(double(g.dims[0]) - 0.5, double(g.dims[1]) - 0.5, double(g.dims[2]) - 0.5);
  auto corner = [&](int i) { return glm::dvec3(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z); };
  // The three edges from the first voxel's corner are the axes, in colour and named at their
  // ends, so that a picture says which way x, y and z run (east, north and up on a geographic
  // grid) without the settings beside it.
  const Rgb8 grey{128, 128, 128};
  const Rgb8 axis_colour[3] = {{200, 60, 60}, {50, 140, 50}, {60, 90, 210}};
  for (int pass = 0; pass < 2; ++pass)  // grey edges first, the axes over them
    for (int a = 0; a < 8; ++a)
      for (int k = 0; k < 3; ++k) {
        const int bit = 1 << k;
        if (a & bit) continue;  // each edge once: from the corner with the bit clear
        const bool axis = a == 0;
        if (axis != (pass == 1)) continue;
        const auto p = project_to_pixel(frame, g, corner(a), image.width, image.height);
        const auto q = project_to_pixel(frame, g, corner(a | bit), image.width, image.height);
        if (!p || !q) continue;
        // Pixel coordinates are centred at integer + 0.5 in draw_line's convention.
        draw_line(image, p->x + 0.5, p->y + 0.5, q->x + 0.5, q->y + 0.5, axis ? axis_colour[k] : grey, 1.0);
        const glm::dvec2 along = *q - *p;
        const double length = glm::length(along);
        if (!axis || length < 12.0) continue;  // an axis seen end-on (z from above) is not named
        const glm::dvec2 at = *q + along / length * 8.0;
        if (at.x >= 4 && at.y >= 5 && at.x + 4 <= image.width && at.y + 5 <= image.height)
          draw_axis_letter(image, k, std::floor(at.x) + 0.5, std::floor(at.y) + 0.5, axis_colour[k]);
      }
  if (!axes) return;
  const auto centre = project_to_pixel(frame, g, 0.5 * (lo + hi), image.width, image.height);
  const auto origin = project_to_pixel(frame, g, corner(0), image.width, image.height);
  if (!centre || !origin) return;
  std::vector<glm::dvec2> dots;  // where draw_markers will draw them, in draw_line's coordinates
  for (const GridIndex& m : markers)
    if (const auto p = project_to_pixel(frame, g, glm::dvec3(double(m[0]), double(m[1]), double(m[2])), image.width,
                                        image.height))
      dots.push_back(*p + 0.5);
  for (int k = 0; k < 3; ++k)
    if (const auto end = project_to_pixel(frame, g, corner(1 << k), image.width, image.height))
      draw_coordinate_ticks(image, frame, g, (*axes)[size_t(k)], k, *origin, *end, *centre, axis_colour[k], dots,
                            marker_radius(image.width, image.height));
}

}  // namespace tfm
