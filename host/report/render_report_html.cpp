// index.html of a report: pictures in a grid, metrics in a table, settings at the end.
#include "tfmatch/report/render_report_html.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace tfm {

std::string html_escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

namespace {

std::string escape(const std::string& text) { return html_escape(text); }

std::string figure(const std::string& file, const std::string& caption) {
  return "<figure><img src=\"" + escape(file) + "\" alt=\"" + escape(caption) + "\"><figcaption>" + escape(caption) +
         "</figcaption></figure>\n";
}

// A row of the metrics table; `better` says which direction improves, and the after cell is
// marked when it moved that way (improved_by_a_margin).
std::string metric_row(const std::string& name, double before, double after, int digits, bool higher_is_better) {
  const bool improved = improved_by_a_margin(before, after, higher_is_better);
  return "<tr><td>" + name + "</td><td>" + report_number(before, digits) + "</td><td" +
         (improved ? " class=\"better\"" : "") + ">" + report_number(after, digits) + "</td><td>" +
         (higher_is_better ? "higher is better" : "lower is better") + "</td></tr>\n";
}

const char* kStyle = R"(
body { font-family: sans-serif; margin: 24px; color: #222; background: #fafafa; }
h1 { font-size: 22px; margin-bottom: 4px; overflow-wrap: anywhere; }
h2 { font-size: 17px; margin-top: 28px; border-bottom: 1px solid #ddd; padding-bottom: 4px; }
h3 { font-size: 15px; margin: 18px 0 6px; overflow-wrap: anywhere; }
.sub { color: #666; font-size: 13px; overflow-wrap: anywhere; }
.grid { display: grid; gap: 14px; align-items: start; }
.g3 { grid-template-columns: repeat(3, minmax(0, 1fr)); }
.g2 { grid-template-columns: repeat(2, minmax(0, 1fr)); }
figure { margin: 0; background: #fff; border: 1px solid #e2e2e2; padding: 6px; }
figure img { width: 100%; height: auto; display: block; image-rendering: auto; }
figcaption { font-size: 13px; color: #444; padding-top: 4px; text-align: center; overflow-wrap: anywhere; }
table { border-collapse: collapse; background: #fff; font-size: 14px; display: block; max-width: 100%; overflow-x: auto; }
td, th { border: 1px solid #ddd; padding: 5px 12px; text-align: right; }
td:first-child, th:first-child { text-align: left; overflow-wrap: anywhere; min-width: 14em; }
td.better { background: #e6f4e6; font-weight: bold; }
pre.cmd { background: #fff; border: 1px solid #e2e2e2; padding: 6px; white-space: pre-wrap; word-break: break-all; }
div.warn { background: #fff4d6; border: 1px solid #e0b84a; padding: 4px 12px; margin: 12px 0; overflow-wrap: anywhere; }
.note { font-size: 12px; color: #666; max-width: 60em; overflow-wrap: anywhere; }
.intro { font-size: 14px; color: #333; max-width: 60em; }
@media (max-width: 700px) {
  body { margin: 10px; }
  .g2, .g3 { grid-template-columns: minmax(0, 1fr); }
}
)";

}  // namespace

bool improved_by_a_margin(double before, double after, bool higher_is_better) {
  const double margin = std::isfinite(before) && std::isfinite(after) ? 0.01 * std::max(std::abs(before), std::abs(after))
                                                                      : 0.0;
  return higher_is_better ? after > before + margin : after < before - margin;
}

std::string report_head(const std::string& title) {
  // A viewport: without it a phone lays the page out 980 px wide and shrinks it; with it the grids
  // stack into one column below 700 px (kStyle).
  return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
         "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>" +
         html_escape(title) + "</title>\n<style>" + kStyle + "</style></head><body>\n";
}

std::string report_number(double v, int digits) {
  if (std::isinf(v)) return "inf";
  if (std::isnan(v)) return "n/a";
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

std::string report_html(const ReportInputs& in, const ReportSummary& s, const nlohmann::json& metrics) {
  const OptimizeResult& r = in.result;
  std::ostringstream h;
  h << report_head(in.title);
  h << "<h1>" << escape(in.title) << "</h1>\n<div class=\"sub\">reference: " << escape(in.ref.name)
    << " &middot; field: " << escape(in.field.name) << " &middot; grid " << in.ref.dims[0] << "&times;"
    << in.ref.dims[1] << "&times;" << in.ref.dims[2] << " &middot; solver: " << escape(r.solver)
    << " &middot; device: " << escape(r.device) << "</div>\n";
  // One sentence for a reader who has not met the method: what is compared, and what is left.
  h << "<p class=\"intro\">The <b>reference</b> field is shown with its transfer function (TF). The <b>second "
       "field</b> is shown twice: with the same TF (before), and with the <b>optimized TF</b>, the one tfmatch "
       "fitted so that its pictures match the reference's as closely as any TF can (after). What still differs "
       "after, the <b>residual</b>, is structure no TF explains.</p>\n";
  for (const std::string& n : in.notes) h << "<p class=\"note\">" << escape(n) << "</p>\n";

  // Every warning of the run (ranges that miss a field, cond(M), clamping) where it is read first.
  if (!r.warnings.empty() || !s.warnings.empty()) {
    h << "<div class=\"warn\"><b>Warnings</b><ul>\n";
    for (const std::string& w : r.warnings) h << "<li>" << escape(w) << "</li>\n";
    for (const std::string& w : s.warnings) h << "<li>" << escape(w) << "</li>\n";
    h << "</ul></div>\n";
  }
  h << "<h2>Renderings</h2>\n";
  if (!in.markers.empty()) {
    h << "<p class=\"note\">" << (in.markers.size() > 1 ? "Red dots: reference points" : "Red dot: reference point");
    for (size_t i = 0; i < in.markers.size(); ++i)
      h << (i ? ", " : " ") << escape(describe_grid_point(in.ref, in.markers[i]));
    h << " (drawn over the volume, visible from every side).</p>\n";
  }
  h << "<div class=\"grid g3\">\n"
    << figure("reference.png", "Reference field, reference TF")
    << figure("field_reference_tf.png", "Second field, reference TF (before)")
    << figure("field_optimized_tf.png", "Second field, optimized TF (after)")
    << figure("tf_reference.png", "Reference TF over the reference histogram")
    << figure("tf_field_reference.png", "Reference TF over the field histogram")
    << figure("tf_optimized.png", "Optimized TF over the field histogram") << "</div>\n";

  h << "<h2>Residual maps</h2>\n<p class=\"note\">Per voxel || premul(T<sub>r</sub>(F<sub>r</sub>)) &minus; "
       "premul(T<sub>o</sub>(F<sub>o</sub>)) ||<sub>2</sub> over RGBA, rendered with the TF below (opacity "
       "linear in the residual) on one scale [0, "
    << report_number(metrics["residual"]["display_range"][1].get<double>(), 4)
    << "] for both, same camera. What remains after optimization is structure no TF can explain.</p>\n"
    << "<div class=\"grid g3\">\n"
    << figure("residual_reference_tf.png", "Residual with the reference TF (before)")
    << figure("residual_optimized_tf.png", "Residual with the optimized TF (after)")
    << figure("tf_residual.png", "Residual TF over the histogram of the residual after") << "</div>\n";

  if (!s.slices.empty()) {
    h << "<h2>Slices</h2>\n<p class=\"note\">Axis-aligned planes through voxel "
      << escape(describe_grid_point(in.ref, s.slice_point))
      << ": each voxel's TF colour at full strength (opacity is what the renderings above show; a slice "
         "shows what the value is, even where the TF makes it nearly transparent); the residual on the scale "
         "above. North and up are up, "
         "the axes labelled with the grid's coordinates; a cross marks the slice point"
      << (in.markers.empty() ? "" : in.markers.size() == 1 ? ", a red dot the marker where it lies in the plane"
                                                            : ", red dots the markers where they lie in the plane")
      << "; a grey checkerboard is no data.</p>\n";
    for (const auto& sl : s.slices) h << figure(sl.file, sl.caption);
  }

  h << "<h2>Metrics</h2>\n<table>\n<tr><th></th><th>reference TF</th><th>optimized TF</th><th></th></tr>\n"
    << metric_row("Image RMSE (0&ndash;255)", s.before.rmse, s.after.rmse, 5, false)
    << metric_row("Image PSNR (dB)", s.before.psnr, s.after.psnr, 5, true)
    << metric_row("Image SSIM", s.before.ssim, s.after.ssim, 5, true)
    << metric_row("Voxel RMSE (RGBA)", r.before.rmse(), r.after.rmse(), 5, false)
    << metric_row("Voxel MAE (RGBA)", r.before.mae(), r.after.mae(), 5, false)
    << metric_row("Residual max", s.residual_max_before, s.residual_max_after, 4, false);
  if (s.residual_inside_before && s.residual_inside_after)
    h << metric_row("Residual inside the changed regions (%)", 100 * *s.residual_inside_before,
                    100 * *s.residual_inside_after, 3, true);
  h << "</table>\n"
    << "<p class=\"note\">Image metrics compare each rendering of the second field with the reference "
       "rendering on the 8-bit sRGB pictures as written to the PNGs (composited over the background in "
       "linear RGB), measured before the box outline and markers are drawn on them. SSIM: Wang et al. 2004, 11&times;11 "
       "Gaussian window (&sigma; = 1.5), K1 = 0.01, K2 = 0.03. LPIPS is not computed (it needs "
       "pretrained network weights). All numbers are in <a href=\"metrics.json\">metrics.json</a>.</p>\n";

  if (!in.extra_figures.empty()) {
    h << "<h2>More</h2>\n<div class=\"grid g2\">\n";
    for (const ReportFigure& f : in.extra_figures) h << figure(f.file, f.title + (f.caption.empty() ? "" : ": " + f.caption));
    h << "</div>\n";
  }

  const RenderSettings& rs = in.settings;
  h << "<h2>Settings</h2>\n<p class=\"note\">" << rs.width << "&times;" << rs.height << " pixels, step "
    << report_number(rs.step_voxels, 4) << " voxels, opacity scale " << report_number(rs.opacity_scale, 4)
    << " per box length, early termination at opacity " << report_number(rs.termination_opacity, 4)
    << "; camera azimuth " << report_number(rs.camera.azimuth_deg, 4) << "&deg;, elevation "
    << report_number(rs.camera.elevation_deg, 4) << "&deg;, "
    << (rs.camera.distance == 0 ? std::string("framed to the box") : "distance " + report_number(rs.camera.distance, 4) + " radii")
    << ", field of view " << report_number(rs.camera.fov_deg, 4) << "&deg;, vertical exaggeration "
    << report_number(rs.z_scale, 4) << ". Ranges: reference ["
    << report_number(r.ref_range.lo, 6) << ", " << report_number(r.ref_range.hi, 6) << "], field ["
    << report_number(r.field_range.lo, 6) << ", " << report_number(r.field_range.hi, 6) << "]. "
    << "A summary picture of this page: <a href=\"overview.png\">overview.png</a>. Pictures are 8-bit sRGB; "
    << "histograms " << (in.histogram_log ? "log(1 + count)" : "linear counts") << ".</p>\n";
  h << "<h2>Reproduce</h2>\n<pre class=\"cmd\">"
    << escape(in.command_line.empty() ? std::string("(written by a library call)") : in.command_line) << "</pre>\n"
    << "<p class=\"note\">" << escape(in.version.empty() ? std::string("tfmatch") : in.version)
    << (metrics.contains("made") ? ". " + escape(report_made_text(metrics["made"])) : std::string())
    << ". Saved here: <a href=\"command.txt\">command.txt</a>, the reference TF as used "
       "(<a href=\"reference_tf.json\">reference_tf.json</a>) and the optimized TF "
       "(<a href=\"optimized_tf.json\">optimized_tf.json</a>), linear RGB tables with their ranges.</p>\n";
  h << "</body></html>\n";
  return h.str();
}

}  // namespace tfm
