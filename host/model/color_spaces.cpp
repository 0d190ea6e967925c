// Colour conversions (sRGB curve, XYZ/Lab with D65 white, Msh, HSV) and interpolation in them.
#include "tfmatch/model/color_spaces.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace tfm {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr Rgb kWhite{0.95047, 1.0, 1.08883};  // D65 reference white in XYZ

double lab_f(double t) { return t > 216.0 / 24389.0 ? std::cbrt(t) : (24389.0 / 27.0 * t + 16.0) / 116.0; }
double lab_f_inv(double f) { return f * f * f > 216.0 / 24389.0 ? f * f * f : (116.0 * f - 16.0) * 27.0 / 24389.0; }

Rgb srgb_to_lab(const Rgb& srgb) {
  const Rgb l = srgb_to_linear(srgb);
  const double x = 0.4124564 * l[0] + 0.3575761 * l[1] + 0.1804375 * l[2];
  const double y = 0.2126729 * l[0] + 0.7151522 * l[1] + 0.0721750 * l[2];
  const double z = 0.0193339 * l[0] + 0.1191920 * l[1] + 0.9503041 * l[2];
  const double fx = lab_f(x / kWhite[0]), fy = lab_f(y / kWhite[1]), fz = lab_f(z / kWhite[2]);
  return {116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)};
}

Rgb lab_to_srgb(const Rgb& lab) {
  const double fy = (lab[0] + 16.0) / 116.0, fx = fy + lab[1] / 500.0, fz = fy - lab[2] / 200.0;
  const double x = kWhite[0] * lab_f_inv(fx), y = kWhite[1] * lab_f_inv(fy), z = kWhite[2] * lab_f_inv(fz);
  Rgb l{3.2404542 * x - 1.5371385 * y - 0.4985314 * z, -0.9692660 * x + 1.8760108 * y + 0.0415560 * z,
        0.0556434 * x - 0.2040259 * y + 1.0572252 * z};
  for (double& c : l) c = std::clamp(c, 0.0, 1.0);
  return linear_to_srgb(l);
}

Rgb lab_to_msh(const Rgb& lab) {
  const double m = std::sqrt(lab[0] * lab[0] + lab[1] * lab[1] + lab[2] * lab[2]);
  return {m, m > 0 ? std::acos(std::clamp(lab[0] / m, -1.0, 1.0)) : 0.0, std::atan2(lab[2], lab[1])};
}

Rgb msh_to_lab(const Rgb& msh) {
  return {msh[0] * std::cos(msh[1]), msh[0] * std::sin(msh[1]) * std::cos(msh[2]), msh[0] * std::sin(msh[1]) * std::sin(msh[2])};
}

// Moreland's hue adjustment: an unsaturated end takes a hue that spins away from the saturated one.
double adjust_hue(const Rgb& saturated, double m_unsaturated) {
  const double m = saturated[0], s = saturated[1], h = saturated[2];
  if (m >= m_unsaturated || std::sin(s) == 0) return h;
  const double spin = s * std::sqrt(m_unsaturated * m_unsaturated - m * m) / (m * std::sin(s));
  return h > -kPi / 3 ? h + spin : h - spin;
}

Rgb diverging(const Rgb& a, const Rgb& b, double w) {
  Rgb m1 = lab_to_msh(srgb_to_lab(a)), m2 = lab_to_msh(srgb_to_lab(b));
  double d = std::abs(m1[2] - m2[2]);
  if (d > kPi) d = 2 * kPi - d;
  // Two distinct saturated colours: pass through an unsaturated (white) midpoint.
  if (m1[1] > 0.05 && m2[1] > 0.05 && d > kPi / 3) {
    const double mid = std::max({m1[0], m2[0], 88.0});
    if (w < 0.5) m2 = {mid, 0, 0}, w *= 2;
    else m1 = {mid, 0, 0}, w = 2 * w - 1;
  }
  if (m1[1] < 0.05 && m2[1] > 0.05) m1[2] = adjust_hue(m2, m1[0]);
  else if (m2[1] < 0.05 && m1[1] > 0.05) m2[2] = adjust_hue(m1, m2[0]);
  Rgb m;
  for (int i = 0; i < 3; ++i) m[i] = (1 - w) * m1[i] + w * m2[i];
  return lab_to_srgb(msh_to_lab(m));
}

Rgb rgb_to_hsv(const Rgb& c) {
  const double mx = std::max({c[0], c[1], c[2]}), mn = std::min({c[0], c[1], c[2]}), d = mx - mn;
  double h = 0;
  if (d > 0) {
    if (mx == c[0]) h = std::fmod((c[1] - c[2]) / d + 6.0, 6.0);
    else if (mx == c[1]) h = (c[2] - c[0]) / d + 2.0;
    else h = (c[0] - c[1]) / d + 4.0;
  }
  return {h / 6.0, mx > 0 ? d / mx : 0.0, mx};
}

Rgb hsv_to_rgb(const Rgb& hsv) {
  const double h = (hsv[0] - std::floor(hsv[0])) * 6.0, s = hsv[1], v = hsv[2];
  const int i = std::min(5, static_cast<int>(h));
  const double f = h - i, p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  switch (i) {
    case 0: return {v, t, p};
    case 1: return {q, v, p};
    case 2: return {p, v, t};
    case 3: return {p, q, v};
    case 4: return {t, p, v};
    default: return {v, p, q};
  }
}

}  // namespace

double srgb_to_linear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }
double linear_to_srgb(double c) { return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055; }
Rgb srgb_to_linear(const Rgb& c) { return {srgb_to_linear(c[0]), srgb_to_linear(c[1]), srgb_to_linear(c[2])}; }
Rgb linear_to_srgb(const Rgb& c) { return {linear_to_srgb(c[0]), linear_to_srgb(c[1]), linear_to_srgb(c[2])}; }

ColorInterpolation parse_paraview_color_space(const std::string& name) {
  if (name == "RGB") return ColorInterpolation::SRgb;
  if (name == "Lab" || name == "CIELAB" || name == "Lab/CIEDE2000") return ColorInterpolation::Lab;
  if (name == "Diverging") return ColorInterpolation::Diverging;
  if (name == "HSV") return ColorInterpolation::Hsv;
  if (name == "Step") return ColorInterpolation::Step;
  throw std::invalid_argument("unknown ColorSpace '" + name + "' (RGB, Lab, CIELAB, Diverging, HSV, Step)");
}

Rgb interpolate_color(const Rgb& a, const Rgb& b, double w, ColorInterpolation space) {
  Rgb out;
  switch (space) {
    case ColorInterpolation::SRgb:
      for (int i = 0; i < 3; ++i) out[i] = (1 - w) * a[i] + w * b[i];
      return out;
    case ColorInterpolation::LinearRgb: {
      const Rgb la = srgb_to_linear(a), lb = srgb_to_linear(b);
      for (int i = 0; i < 3; ++i) out[i] = (1 - w) * la[i] + w * lb[i];
      return linear_to_srgb(out);
    }
    case ColorInterpolation::Lab: {
      const Rgb la = srgb_to_lab(a), lb = srgb_to_lab(b);
      for (int i = 0; i < 3; ++i) out[i] = (1 - w) * la[i] + w * lb[i];
      return lab_to_srgb(out);
    }
    case ColorInterpolation::Diverging: return diverging(a, b, w);
    case ColorInterpolation::Hsv: {
      Rgb ha = rgb_to_hsv(a), hb = rgb_to_hsv(b);
      // Shorter way round the hue circle.
      if (hb[0] - ha[0] > 0.5) ha[0] += 1.0;
      else if (ha[0] - hb[0] > 0.5) hb[0] += 1.0;
      for (int i = 0; i < 3; ++i) out[i] = (1 - w) * ha[i] + w * hb[i];
      return hsv_to_rgb(out);
    }
    case ColorInterpolation::Step: return a;
  }
  return a;
}

}  // namespace tfm
