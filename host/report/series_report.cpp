// The report of a series fit: renderings, plots over the series, the TFs overlaid, index.html.
#include "tfmatch/report/series_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/axis_ticks.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/report/font.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/report/render_report_html.h"
#include "tfmatch/report/report.h"
#include "tfmatch/report/tf_plot.h"

namespace tfm {
namespace {

const Rgb8 kFrame{170, 170, 170}, kGrid{226, 226, 226}, kText{30, 30, 30};

// Ten distinguishable colours for the TFs of a series (the categorical palette matplotlib calls
// tab10), repeated beyond ten.
Rgb8 series_colour(size_t i) {
  static const Rgb8 palette[10] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44},  {214, 39, 40},  {148, 103, 189},
                                   {140, 86, 75},  {227, 119, 194}, {127, 127, 127}, {188, 189, 34}, {23, 190, 207}};
  return palette[i % 10];
}

std::string indexed(const char* pattern, size_t i) {
  char buf[64];
  std::snprintf(buf, sizeof buf, pattern, static_cast<unsigned>(i));
  return buf;
}

double finite_or_nan(double v) { return std::isfinite(v) ? v : NAN; }

}  // namespace

Image plot_series_lines(const std::vector<PlotLine>& lines, uint32_t width, uint32_t height, const std::string& title,
                        const std::string& x_label) {
  if (lines.empty()) throw std::invalid_argument("plot_series_lines: no lines");
  if (width < 200 || height < 120) throw std::invalid_argument("plot_series_lines: plot too small");
  size_t points = 0;
  double lo = INFINITY, hi = -INFINITY;
  for (const PlotLine& l : lines) {
    points = std::max(points, l.values.size());
    for (double v : l.values)
      if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  }
  if (points == 0 || !std::isfinite(lo)) throw std::invalid_argument("plot_series_lines: no points");
  if (hi - lo < 1e-12 * std::max(1.0, std::abs(hi))) lo -= 0.5, hi += 0.5;
  const double pad = 0.06 * (hi - lo);
  lo -= pad;
  hi += pad;
  const std::vector<double> ticks = nice_ticks(lo, hi, 5);
  Image img(width, height);
  int label_width = 0;
  for (double t : ticks) label_width = std::max(label_width, text_width(tick_label(t)));
  const int left = 12 + label_width, right = int(width) - 12;
  const int top = 8 + text_height(1) + 8 + text_height(1) + 4;
  const int bottom = int(height) - 8 - 2 * text_height(1) - 6;
  draw_text(img, 10, 6, title, kText);
  // Legend, on one line under the title.
  int lx = left;
  for (const PlotLine& l : lines) {
    const int y = 8 + text_height(1) + 6 + text_height(1) / 2;
    fill_rect(img, lx, y - 1, 18, 3, l.colour);
    lx += 22 + draw_text(img, lx + 22, y - text_height(1) / 2, l.name, kText) + 14;
  }
  auto px = [&](size_t i) { return left + (points < 2 ? 0.5 : double(i) / double(points - 1)) * (right - left); };
  auto py = [&](double v) { return bottom - (v - lo) / (hi - lo) * (bottom - top); };
  for (double t : ticks) {
    const int y = int(std::lround(py(t)));
    fill_rect(img, left, y, right - left, 1, kGrid);
    draw_text(img, left - 6 - text_width(tick_label(t)), y - text_height(1) / 2, tick_label(t), kText);
  }
  // x ticks: every field when they fit, else about ten.
  const size_t step = std::max<size_t>(1, (points + 9) / 10);
  for (size_t i = 0; i < points; i += step) {
    const std::string label = std::to_string(i);
    draw_text(img, int(px(i)) - text_width(label) / 2, bottom + 4, label, kText);
  }
  draw_text(img, (left + right - text_width(x_label)) / 2, bottom + 6 + text_height(1), x_label, kText);
  for (const PlotLine& l : lines) {
    for (size_t i = 0; i + 1 < l.values.size(); ++i)
      if (std::isfinite(l.values[i]) && std::isfinite(l.values[i + 1]))
        draw_line(img, px(i), py(l.values[i]), px(i + 1), py(l.values[i + 1]), l.colour, 1.5);
    for (size_t i = 0; i < l.values.size(); ++i)
      if (std::isfinite(l.values[i])) fill_rect(img, int(px(i)) - 2, int(py(l.values[i])) - 2, 5, 5, l.colour);
  }
  fill_rect(img, left, top, right - left, 1, kFrame);
  fill_rect(img, left, bottom, right - left, 1, kFrame);
  fill_rect(img, left, top, 1, bottom - top, kFrame);
  fill_rect(img, right - 1, top, 1, bottom - top, kFrame);
  return img;
}

Image plot_tf_overlay(const std::vector<TransferFunction>& tfs, uint32_t width, const std::string& title,
                      const std::optional<FieldRange>& shared_range) {
  if (tfs.empty()) throw std::invalid_argument("plot_tf_overlay: no TFs");
  if (width < 200) throw std::invalid_argument("plot_tf_overlay: plot too small");
  const int strip = tfs.size() > 24 ? 4 : 10, curve_height = 160;
  const int label_width = text_width(std::to_string(tfs.size() - 1)) + 8;
  const int left = 12 + std::max(label_width, text_width("1.0")), right = int(width) - 12;
  const int top = 8 + text_height(1) + 8, bottom = top + curve_height;
  const int ticks = shared_range ? 4 + 2 + text_height(1) + 2 : 0;  // the value axis
  const int strips_top = bottom + 6 + ticks + text_height(1) + 8;
  Image img(width, uint32_t(strips_top + int(tfs.size()) * (strip + 2) + 8));
  draw_text(img, 10, 6, title, kText);
  for (double t : {0.0, 0.5, 1.0}) {
    const int y = int(std::lround(bottom - t * (bottom - top)));
    fill_rect(img, left, y, right - left, 1, kGrid);
    const std::string label = t == 0.0 ? "0" : t == 1.0 ? "1.0" : "0.5";
    draw_text(img, left - 6 - text_width(label), y - text_height(1) / 2, label, kText);
  }
  if (shared_range) draw_value_ticks(img, left, right - 1 - left, bottom + 1, *shared_range, kFrame, kText);
  const std::string axis = shared_range ? std::string("opacity over the values of the range every field shares")
                                        : std::string("opacity over the TF coordinate (0: ") +
                                              (tfs.size() == 1 ? "the range's" : "each field's range's") +
                                              " low end, 1: its high end)";
  draw_text(img, left, bottom + 4 + ticks, axis, kText);
  // The value of TF `tf` at coordinate x in [0, 1] (node-aligned, as the renderer reads it).
  auto at = [](const TransferFunction& tf, double x, int channel) {
    const double u = std::clamp(x, 0.0, 1.0) * double(tf.size() - 1);
    const size_t j = std::min<size_t>(size_t(u), tf.size() - 2);
    const double w = u - double(j);
    return (1.0 - w) * tf.rgba[j][size_t(channel)] + w * tf.rgba[j + 1][size_t(channel)];
  };
  for (size_t k = 0; k < tfs.size(); ++k) {
    const Rgb8 c = series_colour(k);
    double x0 = left, y0 = bottom - at(tfs[k], 0.0, 3) * (bottom - top);
    for (int x = left + 1; x < right; ++x) {
      const double t = double(x - left) / double(right - 1 - left);
      const double y = bottom - at(tfs[k], t, 3) * (bottom - top);
      draw_line(img, x0, y0, x, y, c, 1.2);
      x0 = x, y0 = y;
    }
    // Its colours (linear RGB, shown in sRGB) as a strip, labelled in its curve's colour.
    const int y = strips_top + int(k) * (strip + 2);
    if (strip >= text_height(1) - 4 || k % 5 == 0)
      draw_text(img, left - 6 - text_width(std::to_string(k)), y + strip / 2 - text_height(1) / 2, std::to_string(k), c);
    for (int x = left; x < right; ++x) {
      const double t = double(x - left) / double(right - 1 - left);
      fill_rect(img, x, y, 1, strip, srgb8(at(tfs[k], t, 0), at(tfs[k], t, 1), at(tfs[k], t, 2)));
    }
  }
  fill_rect(img, left, top, right - left, 1, kFrame);
  fill_rect(img, left, bottom, right - left, 1, kFrame);
  return img;
}

std::vector<std::string> series_report_file_names(size_t fields) {
  std::vector<std::string> names{"index.html", "series.json", "reference.png", "rmse.png",
                                 "psnr.png",   "tfs.png",     "tf_reference.png"};
  for (size_t i = 0; i < fields; ++i) {
    names.push_back(indexed("field_%03u_before.png", i));
    names.push_back(indexed("field_%03u.png", i));
    names.push_back(indexed("field_%03u_tf_before.png", i));
    names.push_back(indexed("field_%03u_tf.png", i));
  }
  return names;
}

SeriesReportSummary write_series_report(Context& ctx, const SeriesReportInputs& in, const std::filesystem::path& dir) {
  const SeriesResult& r = in.result;
  const size_t n = r.fields.size();
  if (n == 0 || in.labels.size() != n || !in.load_field)
    throw std::invalid_argument("write_series_report: one label and a loader for every field");
  OutputBatch batch;
  const std::filesystem::path out = batch.directory(dir);
  install_report_font();  // every label in DejaVu Sans when installed
  SeriesReportSummary summary;
  BackgroundPngWriter pngs;  // after the batch: waits for its encodings before the batch cleans up
  auto write = [&](const std::string& name, const Image& img) {
    pngs.add(out / name, img);
    summary.files.push_back(name);
  };
  const RenderSettings& s = in.settings;
  Progress progress("report", n + 1);
  // The renderings show the box outline, as a single field's report does; the metrics are taken
  // without it.
  const VolumeGeometry geometry = VolumeGeometry::from(in.ref.dims, in.ref.spacing, s.z_scale);
  auto outlined = [&](Image img) {
    draw_box_outline(img, geometry, s, &in.ref.axes);
    return img;
  };
  // Every TF over its field's histogram, one plot size for all, so each field's colours have values.
  TfPlotOptions plot;
  plot.width = std::max<uint32_t>(s.width, 320);
  plot.log_counts = in.histogram_log;
  auto tf_plot = [&](const TransferFunction& tf, const Volume& v, const FieldRange& range, const std::string& title) {
    plot.title = title;
    plot.axis_label = field_label(v);
    return plot_transfer_function(tf, v.values, range, plot);
  };
  const Image ref_img = composite_over(render_volume(ctx, in.ref, in.ref_tf, r.ref_range, s), s.background);
  write("reference.png", outlined(ref_img));
  write("tf_reference.png", tf_plot(in.ref_tf, in.ref, r.ref_range, "Reference TF, reference field histogram"));
  progress.update(1);
  for (size_t i = 0; i < n; ++i) {
    const Volume field = in.load_field(i);
    const SeriesFieldResult& f = r.fields[i];
    const Image before = composite_over(render_volume(ctx, field, in.ref_tf, f.field_range, s), s.background);
    const Image after = composite_over(render_volume(ctx, field, f.tf, f.field_range, s), s.background);
    summary.before.push_back(compare_images(ref_img, before));
    summary.after.push_back(compare_images(ref_img, after));
    write(indexed("field_%03u_before.png", i), outlined(before));
    write(indexed("field_%03u.png", i), outlined(after));
    write(indexed("field_%03u_tf_before.png", i), tf_plot(in.ref_tf, field, f.field_range, "Reference TF, field histogram"));
    write(indexed("field_%03u_tf.png", i),
          tf_plot(f.tf, field, f.field_range, r.shared_tf ? "Shared TF, field histogram" : "Its TF, field histogram"));
    progress.update(i + 2);
  }
  progress.finish();

  std::vector<double> rmse_before, rmse_after, psnr_before, psnr_after;
  for (size_t i = 0; i < n; ++i) {
    rmse_before.push_back(r.fields[i].before.rmse());
    rmse_after.push_back(r.fields[i].after.rmse());
    psnr_before.push_back(finite_or_nan(summary.before[i].psnr));
    psnr_after.push_back(finite_or_nan(summary.after[i].psnr));
  }
  const uint32_t plot_width = std::max<uint32_t>(480, std::min<uint32_t>(960, uint32_t(40 * n)));
  const Rgb8 grey{150, 150, 150}, blue{31, 119, 180};
  write("rmse.png", plot_series_lines({{"reference TF", grey, rmse_before}, {r.shared_tf ? "shared TF" : "its own TF", blue, rmse_after}},
                                      plot_width, 240, "voxel RMSE (RGBA) per field", "field"));
  const bool any_psnr = std::any_of(psnr_before.begin(), psnr_before.end(), [](double v) { return std::isfinite(v); }) ||
                        std::any_of(psnr_after.begin(), psnr_after.end(), [](double v) { return std::isfinite(v); });
  if (any_psnr)
    write("psnr.png", plot_series_lines({{"reference TF", grey, psnr_before}, {r.shared_tf ? "shared TF" : "its own TF", blue, psnr_after}},
                                        plot_width, 240, "image PSNR against the reference rendering (dB) per field", "field"));
  std::vector<TransferFunction> tfs;
  if (r.shared_tf) {
    tfs.push_back(r.tf);
  } else {
    for (const SeriesFieldResult& f : r.fields) tfs.push_back(f.tf);
  }
  write("tfs.png", r.shared_tf ? plot_tf_overlay(tfs, 640, "the shared TF", r.fields.front().field_range)
                               : plot_tf_overlay(tfs, 640, "the fitted TFs, one per field"));

  nlohmann::json fields = nlohmann::json::array();
  for (size_t i = 0; i < n; ++i)
    fields.push_back({{"index", i},
                      {"field", in.labels[i]},
                      {"name", r.fields[i].name},
                      {"field_range", {r.fields[i].field_range.lo, r.fields[i].field_range.hi}},
                      {"voxel_rmse_before", rmse_before[i]},
                      {"voxel_rmse_after", rmse_after[i]},
                      {"image_before", summary.before[i].to_json()},
                      {"image_after", summary.after[i].to_json()}});
  const nlohmann::json metrics = {{"solver", r.solver},        {"device", r.device},
                                  {"shared_tf", r.shared_tf},  {"reference", in.ref.name},
                                  {"fields", fields},          {"voxel_rmse_before", r.before.rmse()},
                                  {"voxel_rmse_after", r.after.rmse()}, {"version", in.version},
                                  {"made", report_made(ctx)}};
  pngs.finish();
  write_file_atomically(out / "series.json", json_text(metrics, 2) + "\n");
  summary.files.push_back("series.json");

  const auto better = [](double before, double after, bool higher_is_better) {
    return improved_by_a_margin(before, after, higher_is_better) ? " class=\"better\"" : "";
  };
  std::ostringstream h;
  h << report_head(in.title);
  h << "<h1>" << html_escape(in.title) << "</h1>\n<div class=\"sub\">reference: " << html_escape(in.ref.name) << " &middot; "
    << n << " fields &middot; grid " << in.ref.dims[0] << "&times;" << in.ref.dims[1] << "&times;" << in.ref.dims[2]
    << " &middot; solver " << html_escape(r.solver) << (r.shared_tf ? ", one TF shared by all fields" : ", one TF per field")
    << " &middot; " << html_escape(r.device) << "</div>\n";
  h << "<p class=\"intro\">Every field of the series is shown beside the <b>reference</b>: with the reference's "
       "transfer function (TF, before), and with the TF tfmatch fitted so that its pictures match the reference's as "
       "closely as any TF can (after; "
    << (r.shared_tf ? "one TF shared by every field" : "each field its own") << "). What still differs after is structure "
       "no TF explains.</p>\n";
  for (const std::string& w : r.warnings) h << "<div class=\"warn\">" << html_escape(w) << "</div>\n";
  // Each field's own, by field; more than a few fold under one line so the page still opens on the
  // series.
  size_t field_warnings = 0;
  for (const SeriesFieldResult& f : r.fields) field_warnings += f.warnings.size();
  if (field_warnings > 6) h << "<details><summary>" << field_warnings << " warnings about single fields</summary>\n";
  for (size_t i = 0; i < n; ++i)
    for (const std::string& w : r.fields[i].warnings)
      h << "<div class=\"warn\">" << i << ": " << html_escape(in.labels[i]) << ": " << html_escape(w) << "</div>\n";
  if (field_warnings > 6) h << "</details>\n";
  h << "<h2>Over the series</h2>\n<div class=\"grid g2\">\n"
    << "<figure><img src=\"rmse.png\" alt=\"voxel RMSE per field\"><figcaption>voxel RMSE per field, with the reference TF "
       "and with the fitted TF</figcaption></figure>\n";
  if (any_psnr)
    h << "<figure><img src=\"psnr.png\" alt=\"image PSNR per field\"><figcaption>image PSNR of each field's rendering "
         "against the reference rendering</figcaption></figure>\n";
  else
    h << "<div class=\"note\">No PSNR plot: every field's rendering equals the reference rendering (PSNR infinite, "
         "\"inf\" in series.json).</div>\n";
  h << "</div>\n<h2>Transfer functions</h2>\n<div class=\"grid g2\"><figure><img src=\"tfs.png\" alt=\"the TFs "
       "overlaid\"><figcaption>"
    << (r.shared_tf ? "the shared TF" : "every field's TF: opacity curves overlaid, colours as strips (by field index)")
    << "</figcaption></figure></div>\n";
  h << "<h2>Fields</h2>\n<table>\n<tr><th>field</th><th>range</th><th>voxel RMSE "
       "before</th><th>after</th><th>PSNR before (dB)</th><th>after</th><th>SSIM before</th><th>after</th></tr>\n";
  for (size_t i = 0; i < n; ++i)
    h << "<tr><td>" << i << ": " << html_escape(in.labels[i]) << "</td><td>" << report_number(r.fields[i].field_range.lo, 5)
      << " .. " << report_number(r.fields[i].field_range.hi, 5) << "</td><td>" << report_number(rmse_before[i], 4)
      << "</td><td" << better(rmse_before[i], rmse_after[i], false) << ">" << report_number(rmse_after[i], 4)
      << "</td><td>" << report_number(summary.before[i].psnr, 4) << "</td><td"
      << better(summary.before[i].psnr, summary.after[i].psnr, true) << ">" << report_number(summary.after[i].psnr, 4)
      << "</td><td>" << report_number(summary.before[i].ssim, 4) << "</td><td"
      << better(summary.before[i].ssim, summary.after[i].ssim, true) << ">" << report_number(summary.after[i].ssim, 4)
      << "</td></tr>\n";
  h << "</table>\n<p class=\"note\">Every number of this page, and each field's in full: <a href=\"series.json\">"
       "series.json</a>.</p>\n";
  // Each field beside the reference at one scale: the pictures compared are read side by side,
  // and each TF over its field's histogram beneath, so the colours have values.
  h << "<h2>Renderings</h2>\n";
  const auto fig = [](const std::string& file, const std::string& alt, const std::string& caption) {
    return "<figure><img src=\"" + file + "\" alt=\"" + html_escape(alt) + "\"><figcaption>" + caption +
           "</figcaption></figure>\n";
  };
  for (size_t i = 0; i < n; ++i) {
    const std::string label = std::to_string(i) + ": " + html_escape(in.labels[i]);
    const std::string own = r.shared_tf ? "the shared TF" : "its own TF";
    h << "<h3>" << label << "</h3>\n<div class=\"grid g3\">\n"
      << fig("reference.png", "reference", "reference, its TF")
      << fig(indexed("field_%03u_before.png", i), "field " + std::to_string(i) + " with the reference TF",
             label + ", reference TF (before)")
      << fig(indexed("field_%03u.png", i), "field " + std::to_string(i) + " with " + own, label + ", " + own + " (after)")
      << fig("tf_reference.png", "reference TF plot", "reference TF over the reference histogram")
      << fig(indexed("field_%03u_tf_before.png", i), "reference TF plot", "reference TF over the field's histogram")
      << fig(indexed("field_%03u_tf.png", i), "fitted TF plot", own + " over the field's histogram") << "</div>\n";
  }
  if (!in.command_line.empty()) h << "<h2>Command</h2>\n<pre class=\"cmd\">" << html_escape(in.command_line) << "</pre>\n";
  h << "<div class=\"note\">" << html_escape(in.version) << ". " << html_escape(report_made_text(metrics["made"]))
    << "</div>\n</body></html>\n";
  write_file_atomically(out / "index.html", h.str());
  summary.files.push_back("index.html");
  if (out == dir) remove_earlier_report_files(batch, dir, summary.files);  // an existing directory
  batch.commit();
  summary.index = dir / "index.html";
  return summary;
}

}  // namespace tfm
