// Colour conversions and the interpolation spaces of other tools' transfer functions: sRGB
// transfer curve, CIE L*a*b* (D65), Moreland's Msh "diverging" space and HSV.
#pragma once

#include <array>
#include <string>

namespace tfm {

using Rgb = std::array<double, 3>;

// The sRGB transfer curve (IEC 61966-2-1), per channel, for values in [0,1].
double srgb_to_linear(double c);
double linear_to_srgb(double c);
Rgb srgb_to_linear(const Rgb& c);
Rgb linear_to_srgb(const Rgb& c);

// How colours between two control points are blended. The points hold sRGB-encoded values.
enum class ColorInterpolation {
  SRgb,       // straight lines in sRGB values (ParaView "RGB", the XML format's "sRGB")
  LinearRgb,  // straight lines in linear RGB (the XML format's "Linear RGB")
  Lab,        // CIE L*a*b*
  Diverging,  // Moreland (2009) Msh, with a white midpoint between distinct saturated hues
  Hsv,        // HSV along the shorter hue arc
  Step,       // the left point's colour up to the next point
};

// Parses ParaView's ColorSpace names ("RGB", "Lab", "CIELAB", "Lab/CIEDE2000" (as Lab),
// "Diverging", "HSV", "Step"); throws std::invalid_argument for others.
ColorInterpolation parse_paraview_color_space(const std::string& name);

// The sRGB colour a fraction w in [0,1] of the way from a to b (both sRGB).
Rgb interpolate_color(const Rgb& a, const Rgb& b, double w, ColorInterpolation space);

}  // namespace tfm
