// Loss-curve plot.
#include "tfmatch/report/loss_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "tfmatch/model/axis_ticks.h"
#include "tfmatch/report/font.h"
#include "tfmatch/report/tf_plot.h"

namespace tfm {
Image plot_loss_curve(std::span<const double> curve, uint32_t width, uint32_t height, const std::string& title) {
  if (curve.empty()) throw std::invalid_argument("plot_loss_curve: empty curve");
  if (width < 120 || height < 80) throw std::invalid_argument("plot_loss_curve: plot too small");
  const Rgb8 frame{170, 170, 170}, grid{226, 226, 226}, text{30, 30, 30}, line{200, 40, 40};
  Image img(width, height);
  // Logarithmic axis over the positive values (a loss of exactly 0 sits on the bottom edge).
  double lo = INFINITY, hi = 0.0;
  for (double v : curve)
    if (v > 0 && std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  if (!(hi > 0)) lo = hi = 1.0;
  double l0 = std::floor(std::log10(lo)), l1 = std::ceil(std::log10(hi));
  if (l1 <= l0) l1 = l0 + 1;
  // Every decade labelled where the labels fit one above another, else every k-th.
  const int decades = int(l1 - l0), line_height = text_height(1) + 4;
  int label_width = 0;
  for (int d = 0; d <= decades; ++d) label_width = std::max(label_width, text_width(tick_label(std::pow(10.0, l0 + d), 3)));
  const int left = 10 + label_width, right = int(width) - 10;
  const int top = 8 + text_height(1) + 6, bottom = int(height) - 8 - text_height(1) - 4;
  draw_text(img, 10, 6, title + " (log scale)", text);
  const int every = std::max(1, int(std::ceil(double(decades) * line_height / std::max(1, bottom - top))));
  auto decade_y = [&](double d) { return int(std::lround(bottom - d / (l1 - l0) * (bottom - top))); };
  for (int d = 1; d < decades; ++d) fill_rect(img, left, decade_y(d), right - left, 1, grid);
  auto px = [&](size_t i) { return left + (curve.size() < 2 ? 0.0 : double(i) / double(curve.size() - 1)) * (right - left); };
  auto py = [&](double v) {
    const double l = v > 0 && std::isfinite(v) ? std::log10(v) : l0;
    return bottom - std::clamp((l - l0) / (l1 - l0), 0.0, 1.0) * (bottom - top);
  };
  for (size_t i = 0; i + 1 < curve.size(); ++i) draw_line(img, px(i), py(curve[i]), px(i + 1), py(curve[i + 1]), line, 1.5);
  if (curve.size() == 1) fill_rect(img, int(px(0)) - 1, int(py(curve[0])) - 1, 3, 3, line);
  fill_rect(img, left, top, right - left, 1, frame);
  fill_rect(img, left, bottom, right - left, 1, frame);
  fill_rect(img, left, top, 1, bottom - top, frame);
  fill_rect(img, right - 1, top, 1, bottom - top, frame);
  for (int d = 0; d <= decades; d += every)
    draw_text(img, 6, decade_y(d) - text_height(1) / 2, tick_label(std::pow(10.0, l0 + d), 3), text);
  // Iterations on round ticks, the last one named.
  const double last = double(curve.size() - 1);
  const std::string last_label = "iteration " + tick_label(last, 3);
  const int last_x = right - text_width(last_label);
  int free_from = left;
  for (double t : nice_ticks(0.0, std::max(last, 1.0), 6)) {
    if (t > last) continue;
    const int x = int(std::lround(px(size_t(t))));
    const std::string label = tick_label(t, 3);
    const int lx = std::max(x - text_width(label) / 2, left);
    fill_rect(img, x, bottom, 1, 3, frame);
    if (lx >= free_from && lx + text_width(label) + 6 < last_x) {
      draw_text(img, lx, bottom + 4, label, text);
      free_from = lx + text_width(label) + 6;
    }
  }
  draw_text(img, last_x, bottom + 4, last_label, text);
  return img;
}

std::vector<ReportFigure> solver_report_figures(const OptimizeResult& r, uint32_t width) {
  install_report_font();  // the reports' font, whoever calls first (the CLI draws this before the report)
  const DetailValue* curve_value = r.details.find("loss_curve");
  if (!curve_value || !curve_value->is_list() || curve_value->size() == 0) return {};
  const std::vector<double> curve = curve_value->get<std::vector<double>>();
  const DetailValue* loss_value = r.details.find("loss");
  const std::string loss = loss_value && loss_value->is_text() ? loss_value->get<std::string>() : "image";
  const DetailValue* views = r.details.find("views_per_iteration");
  const std::string title = r.solver + ": mean " + loss + " image loss per iteration";
  std::string caption = "before each step, on that step's cameras (" +
                        std::to_string(views && views->is_number() ? views->get<uint64_t>() : 0) + " views)";
  return {{"Loss curve", "loss.png", plot_loss_curve(curve, std::max<uint32_t>(width, 256), 200, title), caption}};
}

}  // namespace tfm
