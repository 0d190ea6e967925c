// Colour bar beneath a rendering.
#include "tfmatch/model/color_bar.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include "tfmatch/model/axis_ticks.h"

namespace tfm {
namespace {

// `text` in the 5x7 font's ASCII (each other UTF-8 character one '?') within `max_chars`: whole,
// else without what precedes its first ':', else "..." and its end.
std::string fixed_label(const std::string& text, size_t max_chars) {
  std::string ascii;
  for (unsigned char c : text)
    if (c < 0x80) ascii += char(c);
    else if ((c & 0xC0) != 0x80) ascii += '?';  // a lead byte; continuation bytes dropped
  if (ascii.size() <= max_chars) return ascii;
  if (const size_t colon = ascii.find(':'); colon != std::string::npos) ascii.erase(0, colon + 1);
  if (ascii.size() <= max_chars) return ascii;
  return max_chars <= 3 ? std::string() : "..." + ascii.substr(ascii.size() - (max_chars - 3));
}

}  // namespace

std::optional<Image> with_color_bar(const Image& picture, const TransferFunction& tf, const FieldRange& range,
                                    const std::string& title, const std::array<double, 3>& background) {
  if (tf.size() == 0) throw std::invalid_argument("with_color_bar: empty transfer function");
  if (!(range.hi > range.lo)) throw std::invalid_argument("with_color_bar: empty range");
  if (picture.width < kColorBarMinWidth) return std::nullopt;
  const Rgb8 bg = srgb8(background[0], background[1], background[2]);
  Image out(picture.width, picture.height + kColorBarStripHeight, bg);
  std::copy(picture.rgb.begin(), picture.rgb.end(), out.rgb.begin());
  const double luminance = 0.2126 * background[0] + 0.7152 * background[1] + 0.0722 * background[2];
  const bool light = luminance > 0.18;  // about mid-grey as people see it
  const Rgb8 text = light ? Rgb8{40, 40, 40} : Rgb8{225, 225, 225};
  const Rgb8 frame = light ? Rgb8{120, 120, 120} : Rgb8{160, 160, 160};

  // Bar on the right with room for half a label past each end; the title takes what is left.
  const int w = int(picture.width), margin = 8, bar_h = 8, tick_h = 3;
  const int bar_w = std::clamp(w * 2 / 5, 90, 320);
  const int bar_x = w - margin - 12 - bar_w, bar_y = int(picture.height) + 4;
  const int label_y = bar_y + bar_h + 1 + tick_h + 1;
  fill_rect(out, bar_x - 1, bar_y - 1, bar_w + 2, bar_h + 2, frame);
  for (int x = 0; x < bar_w; ++x) {
    const Rgba c = tf.eval((x + 0.5) / bar_w);
    fill_rect(out, bar_x + x, bar_y, 1, bar_h, srgb8(c[0], c[1], c[2]));  // linear TF, shown as sRGB
  }
  int last_right = -1000;
  for (double v : nice_ticks(range.lo, range.hi, std::max(2, bar_w / 50))) {
    const int x = bar_x + int(std::lround((v - range.lo) / (range.hi - range.lo) * (bar_w - 1)));
    const std::string label = tick_label(v, 3);
    const int lw = fixed_text_width(label);
    const int lx = std::min(x - lw / 2, w - 2 - lw);
    if (lx < last_right + 6) continue;  // never overlap the previous label
    fill_rect(out, x, bar_y + bar_h + 1, 1, tick_h, frame);
    draw_fixed_text(out, lx, label_y, label, text);
    last_right = lx + lw;
  }
  const int room = bar_x - 12 - margin;  // the first label may reach 12 pixels left of the bar
  const std::string caption = fixed_label(title, size_t(std::max(0, (room + 1) / 6)));
  draw_fixed_text(out, margin, bar_y + (bar_h - 7) / 2 + 4, caption, text);
  return out;
}

}  // namespace tfm
