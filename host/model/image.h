// Images: the renderer's premultiplied RGBA output, 8-bit RGB pictures, compositing over a
// background, and the few drawing primitives the plots and labelled panels need (with a tiny
// built-in 5x7 bitmap font).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tfm {

using Rgb8 = std::array<uint8_t, 3>;

// 8-bit RGB, rows top to bottom.
struct Image {
  uint32_t width = 0;
  uint32_t height = 0;
  std::vector<uint8_t> rgb;  // 3 bytes per pixel

  Image() = default;
  Image(uint32_t w, uint32_t h, Rgb8 fill = {255, 255, 255});
  uint8_t* at(uint32_t x, uint32_t y) { return rgb.data() + (size_t(y) * width + x) * 3; }
  const uint8_t* at(uint32_t x, uint32_t y) const { return rgb.data() + (size_t(y) * width + x) * 3; }
  void set(int x, int y, Rgb8 c);                // ignores pixels outside
  void blend(int x, int y, Rgb8 c, double alpha);  // c over the pixel with coverage alpha
};

// What a render produces: per pixel premultiplied RGB and opacity before any background, and
// the samples each ray marched (k_stop, which DiffDVR's backward pass starts from).
struct RenderedImage {
  uint32_t width = 0;
  uint32_t height = 0;
  std::vector<float> rgba;        // 4 floats per pixel
  std::vector<uint32_t> stop;     // 1 per pixel
  uint64_t samples() const;       // sum of stop: samples marched
};

// Linear RGB in [0,1] (clamped) to the 8-bit sRGB a PNG holds: the exact piecewise sRGB
// transfer curve, rounded once. Every picture written for people goes through this, so a
// linear 0.5 grey shows as 188 and a ParaView preset's sRGB 0.5 grey as 128, as in ParaView.
uint8_t srgb_byte(double linear);
// The same byte from the formula itself (a pow per call): what srgb_byte's table is built from
// and checked against.
uint8_t srgb_byte_formula(double linear);
Rgb8 srgb8(double r, double g, double b);

// C + (1 - A) * background per channel in linear RGB (the background is linear too), then
// encoded to 8-bit sRGB with srgb_byte.
Image composite_over(const RenderedImage& image, const std::array<double, 3>& background);
Image composite_over(std::span<const double> rgba, uint32_t width, uint32_t height,
                     const std::array<double, 3>& background);

// ---- drawing ------------------------------------------------------------------------------
void fill_rect(Image& img, int x, int y, int w, int h, Rgb8 c);
// A line of `width` pixels, anti-aliased by distance to the segment.
void draw_line(Image& img, double x0, double y0, double x1, double y1, Rgb8 c, double width = 1.0);
// Text with its top-left corner at (x, y), in the installed TextFace (below) if there is one,
// else in the built-in 5x7 font (ASCII 32..126; lower case drawn as small capitals), each font
// pixel drawn as scale x scale. Returns the width drawn.
int draw_text(Image& img, int x, int y, const std::string& text, Rgb8 c, int scale = 1);
int text_width(const std::string& text, int scale = 1);
int text_height(int scale = 1);
// Text in the built-in 5x7 font whatever face is installed: for labels drawn on renderings, which
// must be the same pixels from every command (render, the reports, the viewer). 7 pixels tall.
int draw_fixed_text(Image& img, int x, int y, const std::string& text, Rgb8 c);
int fixed_text_width(const std::string& text);
// `text` when it is at most `max_width` pixels wide, else "..." and the longest end of it that
// fits (a path's end names the file and variable; its start is the least telling), cut at a
// character, not inside a UTF-8 sequence. "" when not even "..." fits.
std::string fit_text(const std::string& text, int max_width, int scale = 1);

// A real font for the pictures people read (host/report/font.h installs one rendered with
// FreeType). Core keeps no font dependency: without a face, text falls back to the bitmap font.
// `scale` 1 is body text (about 13 px), 2 headings.
class TextFace {
 public:
  virtual ~TextFace() = default;
  virtual int draw(Image& img, int x, int y, const std::string& text, Rgb8 c, int scale) const = 0;
  virtual int width(const std::string& text, int scale) const = 0;
  virtual int height(int scale) const = 0;
};
// Installs `face` for every later draw_text (nullptr: the bitmap font); it must outlive its use.
void set_text_face(const TextFace* face);
const TextFace* text_face();  // the installed face (nullptr: the bitmap font)
void blit(Image& dst, const Image& src, int x, int y);
// A filled disc centred at (x, y) in the coordinates of draw_line (pixel (i, j) covers
// [i, i+1) x [j, j+1)), anti-aliased, inside a one-pixel ring of `outline`.
void draw_dot(Image& img, double x, double y, double radius, Rgb8 fill, Rgb8 outline);

// Pictures side by side in rows of `columns`, each with its label centred above it.
struct Panel {
  Image image;
  std::string label;
};
Image compose_panels(const std::vector<Panel>& panels, uint32_t columns, Rgb8 background = {255, 255, 255});

}  // namespace tfm
