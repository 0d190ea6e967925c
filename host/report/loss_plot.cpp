// Loss-curve plot.
#include "tfmatch/report/loss_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace tfm {
namespace {

std::string short_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

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
  const std::string top_label = short_number(std::pow(10.0, l1)), bottom_label = short_number(std::pow(10.0, l0));
  const int left = 10 + std::max(text_width(top_label), text_width(bottom_label)), right = int(width) - 10;
  const int top = 8 + text_height(1) + 6, bottom = int(height) - 8 - text_height(1) - 4;
  draw_text(img, 10, 6, title, text);
  for (double d = l0 + 1; d < l1; d += 1) {
    const int y = int(std::lround(bottom - (d - l0) / (l1 - l0) * (bottom - top)));
    fill_rect(img, left, y, right - left, 1, grid);
  }
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
  draw_text(img, 6, top - text_height(1) / 2, top_label, text);
  draw_text(img, 6, bottom - text_height(1) / 2, bottom_label, text);
  const std::string last = "iteration " + std::to_string(curve.size() - 1);
  draw_text(img, left, bottom + 4, "0", text);
  draw_text(img, right - text_width(last), bottom + 4, last, text);
  return img;
}

std::vector<ReportFigure> solver_report_figures(const OptimizeResult& r, uint32_t width) {
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
