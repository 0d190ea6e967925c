// Image compositing, drawing primitives, the built-in 5x7 font and labelled panels.
#include "tfmatch/model/image.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <stdexcept>

#include "tfmatch/model/color_spaces.h"

namespace tfm {
namespace {

// 5x7 glyphs for ASCII 32..126, one byte per row (bit 4 = leftmost column), top row first.
constexpr uint8_t kFont[95][7] = {
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}, {0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04},  // ' ' !
    {0x0A, 0x0A, 0x0A, 0x00, 0x00, 0x00, 0x00}, {0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A},  // " #
    {0x04, 0x0F, 0x14, 0x0E, 0x05, 0x1E, 0x04}, {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03},  // $ %
    {0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D}, {0x0C, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00},  // & '
    {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}, {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08},  // ( )
    {0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00}, {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00},  // * +
    {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08}, {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00},  // , -
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}, {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00},  // . /
    {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}, {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E},  // 0 1
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}, {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E},  // 2 3
    {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}, {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E},  // 4 5
    {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}, {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08},  // 6 7
    {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}, {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C},  // 8 9
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00}, {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08},  // : ;
    {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02}, {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00},  // < =
    {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08}, {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04},  // > ?
    {0x0E, 0x11, 0x01, 0x0D, 0x15, 0x15, 0x0E}, {0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11},  // @ A
    {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}, {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E},  // B C
    {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}, {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F},  // D E
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}, {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F},  // F G
    {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}, {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E},  // H I
    {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}, {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11},  // J K
    {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}, {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11},  // L M
    {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}, {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},  // N O
    {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}, {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D},  // P Q
    {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}, {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E},  // R S
    {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}, {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},  // T U
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}, {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A},  // V W
    {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}, {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04},  // X Y
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}, {0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E},  // Z [
    {0x00, 0x10, 0x08, 0x04, 0x02, 0x01, 0x00}, {0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E},  // \ ]
    {0x04, 0x0A, 0x11, 0x00, 0x00, 0x00, 0x00}, {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F},  // ^ _
    {0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00}, {0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F},  // ` a
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E}, {0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E},  // b c
    {0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F}, {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E},  // d e
    {0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08}, {0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E},  // f g
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11}, {0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E},  // h i
    {0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C}, {0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12},  // j k
    {0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}, {0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11},  // l m
    {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11}, {0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E},  // n o
    {0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10}, {0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01},  // p q
    {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10}, {0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E},  // r s
    {0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06}, {0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D},  // t u
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04}, {0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A},  // v w
    {0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11}, {0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E},  // x y
    {0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F}, {0x02, 0x04, 0x04, 0x08, 0x04, 0x04, 0x02},  // z {
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}, {0x08, 0x04, 0x04, 0x02, 0x04, 0x04, 0x08},  // | }
    {0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00},                                              // ~
};

}  // namespace

uint8_t srgb_byte_formula(double linear) {
  // NaN clamps to 0 rather than propagating into the cast.
  const double v = std::isnan(linear) ? 0.0 : std::clamp(linear, 0.0, 1.0);
  return static_cast<uint8_t>(std::lround(linear_to_srgb(v) * 255.0));
}

namespace {

// srgb_byte_formula without a pow per channel (three per pixel made composing a 512^2 picture
// cost more than its read-back): the smallest linear value of each byte, found once by bisection
// over the doubles with the formula itself, so the table gives the formula's byte for every input
// (the formula is monotone). Buckets of 1/4096 narrow a lookup to a step or two.
class SrgbBytes {
 public:
  SrgbBytes() {
    for (int b = 1; b < 256; ++b) {
      // Non-negative doubles order as their bit patterns: bisect those, 0.0 below b, 1.0 at 255.
      uint64_t lo = std::bit_cast<uint64_t>(0.0), hi = std::bit_cast<uint64_t>(1.0);
      while (hi - lo > 1) {
        const uint64_t mid = lo + (hi - lo) / 2;
        (srgb_byte_formula(std::bit_cast<double>(mid)) >= b ? hi : lo) = mid;
      }
      first_[size_t(b)] = std::bit_cast<double>(hi);
    }
    for (size_t k = 0; k < kBuckets + 1; ++k) bucket_[k] = srgb_byte_formula(double(k) / kBuckets);
  }
  uint8_t operator()(double linear) const {
    const double v = std::isnan(linear) ? 0.0 : std::clamp(linear, 0.0, 1.0);
    // v * kBuckets is exact (a power of two), so v is at least its bucket's lower end.
    int b = bucket_[size_t(v * kBuckets)];
    while (b < 255 && v >= first_[size_t(b) + 1]) ++b;
    return uint8_t(b);
  }

 private:
  static constexpr size_t kBuckets = 4096;
  std::array<double, 256> first_{};  // first_[b]: the smallest v with formula(v) >= b
  std::array<uint8_t, kBuckets + 1> bucket_{};
};

const SrgbBytes& srgb_bytes() {
  static const SrgbBytes table;
  return table;
}

template <class T>
Image composite(std::span<const T> rgba, uint32_t width, uint32_t height, const std::array<double, 3>& bg) {
  if (rgba.size() != size_t(width) * height * 4) throw std::invalid_argument("composite_over: size mismatch");
  Image out;  // every byte written below: no fill first
  out.width = width;
  out.height = height;
  out.rgb.resize(size_t(width) * height * 3);
  const SrgbBytes& srgb = srgb_bytes();
  for (size_t i = 0; i < size_t(width) * height; ++i) {
    const double a = double(rgba[4 * i + 3]);
    for (int c = 0; c < 3; ++c) out.rgb[3 * i + c] = srgb(double(rgba[4 * i + c]) + (1.0 - a) * bg[c]);
  }
  return out;
}

}  // namespace

uint8_t srgb_byte(double linear) { return srgb_bytes()(linear); }

Rgb8 srgb8(double r, double g, double b) { return {srgb_byte(r), srgb_byte(g), srgb_byte(b)}; }

Image::Image(uint32_t w, uint32_t h, Rgb8 fill) : width(w), height(h), rgb(size_t(w) * h * 3) {
  for (size_t i = 0; i < size_t(w) * h; ++i) std::copy(fill.begin(), fill.end(), rgb.begin() + 3 * i);
}

void Image::set(int x, int y, Rgb8 c) {
  if (x < 0 || y < 0 || x >= int(width) || y >= int(height)) return;
  std::copy(c.begin(), c.end(), at(x, y));
}

void Image::blend(int x, int y, Rgb8 c, double alpha) {
  if (x < 0 || y < 0 || x >= int(width) || y >= int(height) || alpha <= 0) return;
  alpha = std::min(alpha, 1.0);
  uint8_t* p = at(x, y);
  for (int k = 0; k < 3; ++k) p[k] = static_cast<uint8_t>(std::lround(p[k] * (1 - alpha) + c[k] * alpha));
}

uint64_t RenderedImage::samples() const {
  uint64_t n = 0;
  for (uint32_t s : stop) n += s;
  return n;
}

Image composite_over(const RenderedImage& img, const std::array<double, 3>& background) {
  return composite<float>(img.rgba, img.width, img.height, background);
}

Image composite_over(std::span<const double> rgba, uint32_t width, uint32_t height,
                     const std::array<double, 3>& background) {
  return composite<double>(rgba, width, height, background);
}

void fill_rect(Image& img, int x, int y, int w, int h, Rgb8 c) {
  for (int yy = std::max(y, 0); yy < std::min(y + h, int(img.height)); ++yy)
    for (int xx = std::max(x, 0); xx < std::min(x + w, int(img.width)); ++xx) img.set(xx, yy, c);
}

void draw_line(Image& img, double x0, double y0, double x1, double y1, Rgb8 c, double width) {
  const double r = 0.5 * width;
  // Pixels farther than r + 0.5 from the line get no coverage: visit only the image's part of the
  // segment's box, and on each row only the band around the line (a box outline's diagonal edge
  // across a 1024^2 picture visited a million pixels for about two thousand drawn).
  const int xa = std::max(0, int(std::floor(std::min(x0, x1) - r - 1)));
  const int xb = std::min(int(img.width) - 1, int(std::ceil(std::max(x0, x1) + r + 1)));
  const int ya = std::max(0, int(std::floor(std::min(y0, y1) - r - 1)));
  const int yb = std::min(int(img.height) - 1, int(std::ceil(std::max(y0, y1) + r + 1)));
  const double dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy, len = std::sqrt(len2);
  const bool banded = std::abs(dy) > 1e-9 * len;
  for (int y = ya; y <= yb; ++y) {
    int xlo = xa, xhi = xb;
    if (banded) {
      // Distance to the line is |px - xc| |dy| / len on this row, xc where the line crosses it;
      // one pixel of margin each side.
      const double xc = x0 + (y + 0.5 - y0) * dx / dy, half = (r + 0.5) * len / std::abs(dy);
      xlo = std::max(xlo, int(std::floor(xc - half - 0.5)) - 1);
      xhi = std::min(xhi, int(std::ceil(xc + half - 0.5)) + 1);
    }
    for (int x = xlo; x <= xhi; ++x) {
      // Coverage from the distance of the pixel centre to the segment: 1 inside, ramps over 1 px.
      const double px = x + 0.5, py = y + 0.5;
      const double s = len2 > 0 ? std::clamp(((px - x0) * dx + (py - y0) * dy) / len2, 0.0, 1.0) : 0.0;
      const double d = std::hypot(px - (x0 + s * dx), py - (y0 + s * dy));
      img.blend(x, y, c, std::clamp(r + 0.5 - d, 0.0, 1.0));
    }
  }
}

void draw_dot(Image& img, double x, double y, double radius, Rgb8 fill, Rgb8 outline) {
  const double outer = radius + 1.0;
  for (int j = int(std::floor(y - outer - 1)); j <= int(std::ceil(y + outer + 1)); ++j)
    for (int i = int(std::floor(x - outer - 1)); i <= int(std::ceil(x + outer + 1)); ++i) {
      const double d = std::hypot(i + 0.5 - x, j + 0.5 - y);
      img.blend(i, j, outline, std::clamp(outer + 0.5 - d, 0.0, 1.0));
      img.blend(i, j, fill, std::clamp(radius + 0.5 - d, 0.0, 1.0));
    }
}

namespace {

// The face draw_text uses; process-wide so that every plot and panel of a report shares it.
const TextFace* g_face = nullptr;

int draw_bitmap_text(Image& img, int x, int y, const std::string& text, Rgb8 c, int scale) {
  int pen = x;
  for (unsigned char ch : text) {
    const int g = (ch >= 32 && ch <= 126) ? ch - 32 : '?' - 32;
    for (int row = 0; row < 7; ++row)
      for (int col = 0; col < 5; ++col)
        if (kFont[g][row] & (0x10 >> col)) fill_rect(img, pen + col * scale, y + row * scale, scale, scale, c);
    pen += 6 * scale;
  }
  return pen - x;
}

}  // namespace

void set_text_face(const TextFace* face) { g_face = face; }
const TextFace* text_face() { return g_face; }

int draw_text(Image& img, int x, int y, const std::string& text, Rgb8 c, int scale) {
  return g_face ? g_face->draw(img, x, y, text, c, scale) : draw_bitmap_text(img, x, y, text, c, scale);
}

int text_width(const std::string& text, int scale) {
  if (g_face) return g_face->width(text, scale);
  return text.empty() ? 0 : int(text.size()) * 6 * scale - scale;
}

int text_height(int scale) { return g_face ? g_face->height(scale) : 7 * scale; }

int draw_fixed_text(Image& img, int x, int y, const std::string& text, Rgb8 c) {
  return draw_bitmap_text(img, x, y, text, c, 1);
}

int fixed_text_width(const std::string& text) { return text.empty() ? 0 : int(text.size()) * 6 - 1; }

std::string fit_text(const std::string& text, int max_width, int scale) {
  if (text_width(text, scale) <= max_width) return text;
  const std::string dots = "...";
  if (text_width(dots, scale) > max_width) return "";
  for (size_t start = 1; start < text.size(); ++start) {
    if ((static_cast<unsigned char>(text[start]) & 0xC0) == 0x80) continue;  // inside a UTF-8 character
    const std::string candidate = dots + text.substr(start);
    if (text_width(candidate, scale) <= max_width) return candidate;
  }
  return dots;
}

void blit(Image& dst, const Image& src, int x, int y) {
  for (uint32_t yy = 0; yy < src.height; ++yy)
    for (uint32_t xx = 0; xx < src.width; ++xx) {
      const uint8_t* p = src.at(xx, yy);
      dst.set(x + int(xx), y + int(yy), {p[0], p[1], p[2]});
    }
}

Image compose_panels(const std::vector<Panel>& panels, uint32_t columns, Rgb8 background) {
  if (panels.empty() || columns == 0) throw std::invalid_argument("compose_panels: nothing to compose");
  const int margin = 12, scale = 2, label_h = text_height(scale) + 10;
  uint32_t cell_w = 0, cell_h = 0;
  for (const Panel& p : panels) {
    cell_w = std::max<uint32_t>({cell_w, p.image.width, uint32_t(text_width(p.label, scale))});
    cell_h = std::max(cell_h, p.image.height);
  }
  const uint32_t cols = std::min<uint32_t>(columns, uint32_t(panels.size()));
  const uint32_t rows = uint32_t((panels.size() + cols - 1) / cols);
  Image out(cols * (cell_w + margin) + margin, rows * (cell_h + label_h + margin) + margin, background);
  for (size_t i = 0; i < panels.size(); ++i) {
    const int cx = margin + int(i % cols) * int(cell_w + margin);
    const int cy = margin + int(i / cols) * int(cell_h + label_h + margin);
    const Panel& p = panels[i];
    draw_text(out, cx + (int(cell_w) - text_width(p.label, scale)) / 2, cy, p.label, {20, 20, 20}, scale);
    blit(out, p.image, cx + (int(cell_w) - int(p.image.width)) / 2, cy + label_h);
  }
  return out;
}

}  // namespace tfm
