// Transfer-function plot: histogram, opacity curve and colour bar.
#include "tf_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace tfm {
namespace {

std::string short_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

}  // namespace

std::vector<uint64_t> field_histogram(std::span<const float> values, const FieldRange& range, uint32_t bins) {
  if (bins == 0 || !(range.hi > range.lo)) throw std::invalid_argument("field_histogram: empty range or no bins");
  std::vector<uint64_t> counts(bins, 0);
  const double scale = double(bins) / (range.hi - range.lo);
  for (float v : values) {
    if (std::isnan(v)) continue;
    const double x = std::clamp((double(v) - range.lo) * scale, 0.0, double(bins) - 1.0);
    ++counts[static_cast<size_t>(x)];
  }
  return counts;
}

Image plot_transfer_function(const TransferFunction& tf, std::span<const float> values, const FieldRange& range,
                             const TfPlotOptions& o) {
  if (o.width < 64 || o.height < 80) throw std::invalid_argument("plot_transfer_function: plot too small");
  if (tf.size() < 2) throw std::invalid_argument("plot_transfer_function: TF needs 2 entries");
  const Rgb8 frame{170, 170, 170}, text{30, 30, 30}, hist_fill{242, 226, 150}, curve{25, 25, 25};
  Image img(o.width, o.height);
  const int left = 8, right = int(o.width) - 8;
  const int top = o.title.empty() ? 8 : 8 + text_height(1) + 6;
  const int bar_h = 14, label_h = text_height(1) + 4;
  const int plot_bottom = int(o.height) - 6 - label_h - bar_h - 3;
  const int plot_w = right - left, plot_h = plot_bottom - top;
  if (!o.title.empty()) draw_text(img, left, 6, o.title, text);

  // Histogram: one bar per pixel column.
  const auto counts = field_histogram(values, range, uint32_t(plot_w));
  const uint64_t peak = *std::max_element(counts.begin(), counts.end());
  for (int x = 0; x < plot_w && peak > 0; ++x) {
    const double f = o.log_counts ? std::log1p(double(counts[x])) / std::log1p(double(peak))
                                  : double(counts[x]) / double(peak);
    const int bar = int(std::lround(f * plot_h));
    fill_rect(img, left + x, plot_bottom - bar, 1, bar, hist_fill);
  }
  // Light grid at opacity 0.25, 0.5, 0.75.
  for (int k = 1; k < 4; ++k) fill_rect(img, left, plot_bottom - k * plot_h / 4, plot_w, 1, {226, 226, 226});

  // Opacity curve through the TF entries at their node positions t_j = j / (N - 1).
  const size_t n = tf.size();
  auto px = [&](double t) { return left + t * plot_w; };
  auto py = [&](double a) { return plot_bottom - std::clamp(a, 0.0, 1.0) * plot_h; };
  for (size_t j = 0; j + 1 < n; ++j)
    draw_line(img, px(double(j) / (n - 1)), py(tf.rgba[j][3]), px(double(j + 1) / (n - 1)), py(tf.rgba[j + 1][3]),
              curve, 2.0);

  // Frame around the plot area, then the colour bar (RGB of T(t) at each column's centre).
  fill_rect(img, left, top, plot_w, 1, frame);
  fill_rect(img, left, plot_bottom, plot_w, 1, frame);
  fill_rect(img, left, top, 1, plot_h, frame);
  fill_rect(img, right - 1, top, 1, plot_h, frame);
  const int bar_top = plot_bottom + 3;
  for (int x = 0; x < plot_w; ++x) {
    const Rgba c = tf.eval((x + 0.5) / plot_w);
    const Rgb8 rgb{uint8_t(std::lround(std::clamp(c[0], 0.0, 1.0) * 255)),
                   uint8_t(std::lround(std::clamp(c[1], 0.0, 1.0) * 255)),
                   uint8_t(std::lround(std::clamp(c[2], 0.0, 1.0) * 255))};
    fill_rect(img, left + x, bar_top, 1, bar_h, rgb);
  }
  const int label_y = bar_top + bar_h + 4;
  draw_text(img, left, label_y, short_number(range.lo), text);
  const std::string hi = short_number(range.hi);
  draw_text(img, right - text_width(hi), label_y, hi, text);
  return img;
}

}  // namespace tfm
