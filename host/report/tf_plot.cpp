// Transfer-function plot: histogram, opacity curve and colour bar.
#include "tfmatch/report/tf_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace tfm {
std::vector<uint64_t> field_histogram(std::span<const float> values, const FieldRange& range, uint32_t bins) {
  if (bins == 0 || !(range.hi > range.lo)) throw std::invalid_argument("field_histogram: empty range or no bins");
  std::vector<uint64_t> counts(bins, 0);
  const double scale = double(bins) / (range.hi - range.lo);
  for (float v : values) {
    if (no_data(v)) continue;  // NaN and ±Inf (an infinite value clamped into an end bin was counted)
    const double x = std::clamp((double(v) - range.lo) * scale, 0.0, double(bins) - 1.0);
    ++counts[static_cast<size_t>(x)];
  }
  return counts;
}

int draw_value_ticks(Image& img, int left, int width, int y, const FieldRange& range, Rgb8 tick, Rgb8 text) {
  const int tick_h = 4, label_y = y + tick_h + 2;
  int last_right = -1000;
  for (double v : nice_ticks(range.lo, range.hi, std::max(2, width / 90))) {
    const int x = int(std::lround(left + (v - range.lo) / (range.hi - range.lo) * width));
    fill_rect(img, std::min(x, left + width - 1), y, 1, tick_h, tick);
    const std::string label = tick_label(v);
    const int w = text_width(label);
    const int lx = std::clamp(x - w / 2, 2, int(img.width) - 2 - w);
    if (lx < last_right + 6) continue;  // never overlap the previous label
    draw_text(img, lx, label_y, label, text);
    last_right = lx + w;
  }
  return label_y + text_height(1);
}

std::string field_label(const Volume& v) {
  const std::string& name = v.name;
  const size_t slash = name.find_last_of('/');
  const std::string label = slash == std::string::npos ? name : name.substr(slash + 1);
  return v.units.empty() ? label : label + " (" + v.units + ")";
}

// A value axis's caption within `width` pixels: whole where it fits; else without the file
// ("file.grib:t,member=3 (K)" as "t,member=3 (K)": the variable is what the axis shows); else as
// much of that end as fits.
std::string axis_caption(const std::string& label, int width) {
  if (text_width(label) <= width) return label;
  const size_t colon = label.find(':');
  const std::string variable = colon == std::string::npos ? label : label.substr(colon + 1);
  return fit_text(variable, width);
}

Image plot_transfer_function(const TransferFunction& tf, std::span<const float> values, const FieldRange& range,
                             const TfPlotOptions& o) {
  if (o.width < 160 || o.height < 140) throw std::invalid_argument("plot_transfer_function: plot too small");
  if (tf.size() < 2) throw std::invalid_argument("plot_transfer_function: TF needs 2 entries");
  const Rgb8 frame{170, 170, 170}, text{30, 30, 30}, muted{100, 100, 100}, hist_fill{242, 226, 150}, curve{25, 25, 25};
  Image img(o.width, o.height);
  const int th = text_height(1);
  // Left: opacity tick labels; bottom: colour bar, value ticks, the axis label.
  const int left = 8 + text_width("0.5") + 6, right = int(o.width) - 12;
  // Which histogram this is: beside the title, right-aligned, where the title leaves room; else
  // on a line of its own under the title, never over the plot (the opacity curve of a ramp ends
  // in its top-right corner).
  const std::string scale = o.log_counts ? "histogram: log(1 + count)" : "histogram: count";
  const bool scale_beside_title =
      !o.title.empty() && 8 + text_width(o.title) + 12 + text_width(scale) <= right;
  const int scale_line = scale_beside_title ? 0 : th + 4;
  const int top = (o.title.empty() ? 8 : 8 + th + 6) + scale_line;
  const int bar_h = 12, tick_h = 4;
  const int bottom_block = 3 + bar_h + tick_h + 2 + th + (o.axis_label.empty() ? 0 : th + 2) + 6;
  const int plot_bottom = int(o.height) - bottom_block;
  const int plot_w = right - left, plot_h = plot_bottom - top;
  if (plot_h < 20) throw std::invalid_argument("plot_transfer_function: plot too small for its labels");
  if (!o.title.empty()) draw_text(img, 8, 6, fit_text(o.title, right - 8), text);

  // Histogram: one bar per pixel column.
  const auto counts = field_histogram(values, range, uint32_t(plot_w));
  const uint64_t peak = *std::max_element(counts.begin(), counts.end());
  for (int x = 0; x < plot_w && peak > 0; ++x) {
    const double f = o.log_counts ? std::log1p(double(counts[x])) / std::log1p(double(peak))
                                  : double(counts[x]) / double(peak);
    const int bar = int(std::lround(f * plot_h));
    fill_rect(img, left + x, plot_bottom - bar, 1, bar, hist_fill);
  }
  // Light grid at opacity 0.25, 0.5, 0.75; opacity ticks 0, 0.5, 1 on the left.
  for (int k = 1; k < 4; ++k) fill_rect(img, left, plot_bottom - k * plot_h / 4, plot_w, 1, {226, 226, 226});
  for (auto [a, label] : {std::pair{0.0, "0"}, std::pair{0.5, "0.5"}, std::pair{1.0, "1"}}) {
    const int y = plot_bottom - int(std::lround(a * plot_h));
    fill_rect(img, left - 4, y, 4, 1, frame);
    draw_text(img, left - 6 - text_width(label), y - th / 2, label, muted);
  }

  // Opacity curve through the TF entries at their node positions t_j = j / (N - 1).
  const size_t n = tf.size();
  auto px = [&](double t) { return left + t * plot_w; };
  auto py = [&](double a) { return plot_bottom - std::clamp(a, 0.0, 1.0) * plot_h; };
  for (size_t j = 0; j + 1 < n; ++j)
    draw_line(img, px(double(j) / (n - 1)), py(tf.rgba[j][3]), px(double(j + 1) / (n - 1)), py(tf.rgba[j + 1][3]),
              curve, 2.0);

  // Frame around the plot area, then the colour bar (T(t) at each column's centre, in sRGB).
  fill_rect(img, left, top, plot_w, 1, frame);
  fill_rect(img, left, plot_bottom, plot_w, 1, frame);
  fill_rect(img, left, top, 1, plot_h, frame);
  fill_rect(img, right - 1, top, 1, plot_h, frame);
  if (scale_beside_title) {
    draw_text(img, right - text_width(scale), 6, scale, muted);
  } else {
    const std::string fitted = fit_text(scale, plot_w);
    draw_text(img, right - text_width(fitted), top - scale_line - 2, fitted, muted);
  }
  const int bar_top = plot_bottom + 3;
  for (int x = 0; x < plot_w; ++x) {
    const Rgba c = tf.eval((x + 0.5) / plot_w);
    fill_rect(img, left + x, bar_top, 1, bar_h, srgb8(c[0], c[1], c[2]));  // linear TF, shown as sRGB
  }
  const int label_y = draw_value_ticks(img, left, plot_w, bar_top + bar_h, range, muted, text) - th;
  if (!o.axis_label.empty()) {
    const std::string label = axis_caption(o.axis_label, int(o.width) - 8);
    const int lx = std::clamp(left + (plot_w - text_width(label)) / 2, 4, std::max(4, int(o.width) - 4 - text_width(label)));
    draw_text(img, lx, label_y + th + 2, label, muted);
  }
  return img;
}

}  // namespace tfm
