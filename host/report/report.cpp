// Report generation: renders and plots on the device, measures the images, writes PNGs,
// metrics.json, overview.png and index.html (host/report/render_report_html.cpp).
#include "tfmatch/report/report.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <regex>
#include <sstream>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/tf_json.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/shell_words.h"
#include "tfmatch/model/slice.h"
#include "tfmatch/report/font.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/report/render_report_html.h"
#include "tfmatch/report/result_json.h"
#include "tfmatch/report/series_report.h"
#include "tfmatch/report/tf_plot.h"

namespace tfm {
namespace {

double max_value(const Volume& v) {
  double m = 0.0;
  for (float x : v.values)
    if (std::isfinite(x)) m = std::max(m, double(x));
  return m;
}

// Rows of panels stacked top to bottom, each row centred.
Image stack_rows(const std::vector<Image>& rows, Rgb8 background) {
  uint32_t w = 0, h = 0;
  for (const Image& r : rows) w = std::max(w, r.width), h += r.height;
  Image out(w, h, background);
  int y = 0;
  for (const Image& r : rows) {
    blit(out, r, int(w - r.width) / 2, y);
    y += int(r.height);
  }
  return out;
}

// The numbers as a picture, for overview.png (the HTML page has them as a table): three columns
// at fixed positions (the font is proportional), then the warnings, wrapped to the panel.
// The share of the residual map's sum (finite voxels) that lies where `mask` is set; 0 when the
// residual is 0 everywhere.
double fraction_inside(const Volume& residual, const std::vector<uint8_t>& mask) {
  if (mask.size() != residual.values.size())
    throw std::runtime_error("the changed-regions mask has " + std::to_string(mask.size()) + " voxels, the fields " +
                             std::to_string(residual.values.size()));
  double inside = 0, all = 0;
  for (size_t i = 0; i < mask.size(); ++i) {
    const float r = residual.values[i];
    if (!std::isfinite(r)) continue;
    all += r;
    if (mask[i]) inside += r;
  }
  return all > 0 ? inside / all : 0.0;
}

Image metrics_panel(const ReportSummary& s, const OptimizeResult& r, uint32_t width, uint32_t height) {
  const Rgb8 ink{30, 30, 30}, muted{110, 110, 110}, warn{150, 80, 0};
  struct Row {
    std::string name, before, after;
  };
  auto row = [](const std::string& name, double before, double after, int digits) {
    return Row{name, report_number(before, digits), report_number(after, digits)};
  };
  std::vector<Row> rows = {{"", "ref TF", "opt TF"},
                                 row("image RMSE", s.before.rmse, s.after.rmse, 4),
                                 row("PSNR dB", s.before.psnr, s.after.psnr, 4),
                                 row("SSIM", s.before.ssim, s.after.ssim, 3),
                                 row("voxel RMSE", r.before.rmse(), r.after.rmse(), 3),
                                 row("residual max", s.residual_max_before, s.residual_max_after, 3)};
  if (s.residual_inside_before && s.residual_inside_after)
    rows.push_back({"in changed", report_number(100 * *s.residual_inside_before, 2) + "%",
                   report_number(100 * *s.residual_inside_after, 2) + "%"});
  // Scale 2 when the table fits, else 1 (small images).
  auto widths = [&](int scale) {
    int a = 0, b = 0, c = 0;
    for (const Row& x : rows)
      a = std::max(a, text_width(x.name, scale)), b = std::max(b, text_width(x.before, scale)),
      c = std::max(c, text_width(x.after, scale));
    return std::array<int, 3>{a, b, c};
  };
  // The table and the solver line: scale 2 where they fit the picture's width and height, else 1
  // (small pictures), and the panel grows to hold them at scale 1 (at 240 x 120 the last rows
  // were cut through).
  auto table_size = [&](int scale) {
    const auto w = widths(scale);
    const int line = text_height(scale) + 3 * scale;
    return std::pair{w[0] + w[1] + w[2] + 2 * 8 * scale + 24, 12 + int(rows.size() + 1) * line + 4};
  };
  const auto [w2, h2] = table_size(2);
  const int scale = w2 <= int(width) && h2 <= int(height) ? 2 : 1;
  const auto [needed_w, needed_h] = table_size(scale);
  width = std::max<uint32_t>(width, uint32_t(needed_w));
  height = std::max<uint32_t>(height, uint32_t(needed_h));
  Image img(width, height);
  const auto w = widths(scale);
  const int gap = 8 * scale, line = text_height(scale) + 3 * scale;
  int y = 12;
  for (size_t i = 0; i < rows.size(); ++i) {
    const Rgb8 c = i == 0 ? muted : ink;
    draw_text(img, 12, y, rows[i].name, c, scale);
    draw_text(img, 12 + w[0] + gap, y, rows[i].before, c, scale);
    draw_text(img, 12 + w[0] + w[1] + 2 * gap, y, rows[i].after, c, scale);
    y += line;
  }
  draw_text(img, 12, y, "solver: " + r.solver, muted, scale);
  y += line + 4;
  // Warnings, word-wrapped at scale 1, whole ones as many as fit; the rest are counted on the last
  // line (the page lists them all).
  const int th = text_height(1);
  for (size_t k = 0; k < r.warnings.size(); ++k) {
    std::vector<std::string> lines;
    std::string current = "warning:";
    std::istringstream words(r.warnings[k]);
    for (std::string word; words >> word;) {
      if (text_width(current + " " + word, 1) > int(width) - 24) {
        lines.push_back(current);
        current = "  " + word;
      } else {
        current += " " + word;
      }
    }
    lines.push_back(current);
    const bool last = k + 1 == r.warnings.size();
    const int room_for_note = last ? 0 : th + 2;
    if (y + int(lines.size()) * (th + 2) + room_for_note > int(height)) {
      const size_t left = r.warnings.size() - k;
      draw_text(img, 12, y, fit_text(std::to_string(left) + (left == 1 ? " more warning" : " more warnings") +
                                         " on the report page", int(width) - 24), warn, 1);
      return img;
    }
    for (const std::string& l : lines) {
      draw_text(img, 12, y, l, warn, 1);
      y += th + 2;
    }
    y += 4;
  }
  return img;
}

nlohmann::json settings_json(const RenderSettings& s) {
  return {{"width", s.width},
          {"height", s.height},
          {"step_voxels", s.step_voxels},
          {"opacity_scale", s.opacity_scale},
          {"background", s.background},
          {"termination_opacity", s.termination_opacity},
          {"background_encoding", "linear RGB (PNGs are sRGB)"},
          {"z_scale", s.z_scale},
          {"box_outline", s.box_outline},
          {"camera",
           {{"azimuth_deg", s.camera.azimuth_deg},
            {"elevation_deg", s.camera.elevation_deg},
            {"distance", s.camera.distance},
            {"fov_deg", s.camera.fov_deg}}}};
}

// The slices through in.slice_point (default: the first marker, else the middle), one picture per axis with the four
// quantities side by side: the plane normal to z first (a map view for geophysical grids).
template <class Save>
void write_slices(const ReportInputs& in, const Volume& residual, const TransferFunction& res_tf,
                  const FieldRange& res_range, ReportSummary& out, Save& save) {
  const auto& d = in.ref.dims;
  out.slice_point = in.slice_point ? *in.slice_point
                                   : (!in.markers.empty() ? in.markers.front() : GridIndex{d[0] / 2, d[1] / 2, d[2] / 2});
  const OptimizeResult& r = in.result;
  SliceStyle style;
  style.background = in.settings.background;
  style.z_scale = in.settings.z_scale;
  style.max_size = std::clamp<uint32_t>(in.settings.width * 3 / 4, 160, 480);
  style.opacity_scale = max_opacity(in.ref_tf);  // (opacity shading) one scale for the three classified fields
  SliceStyle res_style = style;
  res_style.opacity_scale = max_opacity(res_tf);
  static const char* names[3] = {"x", "y", "z"};
  for (int axis : {2, 1, 0}) {
    const SliceValues ref = extract_slice(in.ref, axis, out.slice_point[size_t(axis)]);
    if (ref.width < 2 || ref.height < 2) continue;  // a line, not a plane
    const SliceValues field = extract_slice(in.field, axis, out.slice_point[size_t(axis)]);
    const SliceValues res = extract_slice(residual, axis, out.slice_point[size_t(axis)]);
    // The slice point crossed and the renderings' markers dotted where they lie in the plane.
    auto labelled = [&](const Volume& v, const SliceValues& sv, const TransferFunction& tf, const FieldRange& range,
                        const SliceStyle& st) {
      Image picture = slice_image(v, sv, tf, range, st);
      mark_slice(picture, sv, {out.slice_point}, in.markers);
      return label_slice_axes(picture, v, sv);
    };
    const Image row = compose_panels({{labelled(in.ref, ref, in.ref_tf, r.ref_range, style), "Reference"},
                                      {labelled(in.field, field, in.ref_tf, r.field_range, style), "Field, reference TF"},
                                      {labelled(in.field, field, r.tf, r.field_range, style), "Field, optimized TF"},
                                      {labelled(residual, res, res_tf, res_range, res_style), "Residual, optimized TF"}},
                                     4);
    const std::string file = std::string("slices_") + names[axis] + ".png";
    save(file, row);
    out.slices.push_back({file, describe_slice(in.ref, axis, out.slice_point[size_t(axis)])});
  }
}

}  // namespace

std::vector<std::string> report_file_names() {
  return {"reference.png",       "field_reference_tf.png", "field_optimized_tf.png", "residual_reference_tf.png",
          "residual_optimized_tf.png", "tf_reference.png",  "tf_field_reference.png", "tf_optimized.png",
          "tf_residual.png",     "loss.png",               "overview.png",           "metrics.json",
          "command.txt",         "reference_tf.json",      "optimized_tf.json",      "slices_x.png",
          "slices_y.png",        "slices_z.png",           "inputs.json",            "index.html"};
}

void remove_earlier_report_files(OutputBatch& batch, const std::filesystem::path& dir,
                                 const std::vector<std::string>& written) {
  std::vector<std::string> names = report_file_names();
  for (const std::string& n : series_report_file_names(0)) names.push_back(n);
  // A series report's per-field pictures: field_000.png, field_000_before.png, ... for any count.
  static const std::regex field_picture(R"(field_\d{3,}(_before|_tf_before|_tf)?\.png)");
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    const bool report_file = std::find(names.begin(), names.end(), name) != names.end() ||
                             std::regex_match(name, field_picture);
    if (report_file && entry.is_regular_file(ec) && std::find(written.begin(), written.end(), name) == written.end())
      batch.remove_on_commit(entry.path());
  }
}

nlohmann::json report_made(const Context& ctx) {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char when[32];
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M UTC", &utc);
  return {{"time_utc", when}, {"device", ctx.device_name()}, {"driver", ctx.driver_description()}};
}

std::string report_made_text(const nlohmann::json& made) {
  return "Made " + made.value("time_utc", std::string("?")) + " on " + made.value("device", std::string("?")) + " (" +
         made.value("driver", std::string("?")) + ")";
}

double background_fraction(const Image& img, const std::array<double, 3>& background) {
  const Rgb8 bg = srgb8(background[0], background[1], background[2]);
  const size_t n = size_t(img.width) * img.height;
  if (n == 0) return 0.0;
  size_t same = 0;
  for (size_t p = 0; p < n; ++p) {
    bool near = true;
    for (int c = 0; c < 3; ++c) near &= std::abs(int(img.rgb[3 * p + size_t(c)]) - int(bg[size_t(c)])) <= 16;
    same += near;
  }
  return double(same) / double(n);
}

void check_report_memory(const Context& ctx, uint64_t voxels, const RenderSettings& s) {
  check_render_size(ctx, s);
  // At most: both fields, a residual map being made and one being rendered on the device (on a
  // device that reads host memory in place, only the map being made); both maps on the host.
  // Pictures: a rendering's read-back (check_render_size) and about a dozen RGBA images kept for
  // the overview and the encoder.
  const uint64_t volume = voxels * sizeof(float), device = (DeviceField::reads_host_memory(ctx) ? 1 : 3) * volume;
  const uint64_t host = 2 * volume;
  const uint64_t pictures = uint64_t(s.width) * s.height * (23 + 12 * 4);
  const std::string what = "report: both fields and a residual map on the device, two residual maps and the pictures";
  if (device_memory_is_host(ctx)) {
    check_device_memory(ctx, device + host + pictures, what);
  } else {
    check_device_memory(ctx, device, what);
    check_memory(host + pictures, what);
  }
}

ReportSummary write_report(Context& ctx, const ReportInputs& in, const std::filesystem::path& final_dir) {
  require_same_grid(in.ref, in.field);
  const OptimizeResult& r = in.result;
  const RenderSettings& s = in.settings;
  validate(s);
  if (in.slice_point)
    for (int k = 0; k < 3; ++k)
      if ((*in.slice_point)[size_t(k)] >= in.ref.dims[size_t(k)])
        throw std::runtime_error("report: slice point " + describe_grid_point(in.ref, *in.slice_point) +
                                 " is outside the grid");
  check_report_memory(ctx, in.ref.values.size(), s);
  // Everything goes to temporary names (a staged directory when `final_dir` is new) that appear
  // together when the report is complete, or, inside a command's batch, when the command is.
  OutputBatch batch;
  const std::filesystem::path dir = batch.directory(final_dir);
  const std::string font = install_report_font();  // every label below in DejaVu Sans when installed
  ReportSummary out;
  Progress progress("report", 10);
  uint64_t step = 0;
  auto advance = [&](const char* what) {
    checkpoint("report");
    progress.set_label(std::string("report: ") + what);
    progress.update(++step);
  };
  // Declared after the batch: on an error its destructor waits for the encodings before the
  // batch removes what was written.
  BackgroundPngWriter pngs;
  auto save = [&](const std::string& name, const Image& img) {
    pngs.add(dir / name, img);
    out.files.push_back(name);
  };

  // Both fields and the three TF tables on the device once; every picture below reuses them, and
  // the residual maps (host and device copies) come on top (check_report_memory).
  const VolumeGeometry geometry = VolumeGeometry::from(in.ref.dims, in.ref.spacing, s.z_scale);
  const DeviceField ref = field_over_host_values(ctx, in.ref.values, "report: reference field");
  const DeviceField field = field_over_host_values(ctx, in.field.values, "report: second field", ref.chunk_voxels());
  Buffer ref_tf = upload_tf(ctx, in.ref_tf, "report: reference TF");
  Buffer opt_tf = upload_tf(ctx, r.tf, "report: optimized TF");
  const uint32_t ref_n = uint32_t(in.ref_tf.size()), opt_n = uint32_t(r.tf.size());
  const FieldMapping ref_map = make_mapping(r.ref_range, ref_n);
  const FieldMapping field_ref_tf_map = make_mapping(r.field_range, ref_n);
  const FieldMapping field_opt_tf_map = make_mapping(r.field_range, opt_n);
  GpuRenderer ref_renderer(ctx, ref, geometry);
  GpuRenderer field_renderer(ctx, field, geometry);

  advance("rendering the reference");
  Image ref_img = composite_over(ref_renderer.render(ref_map, ref_tf, s), s.background);
  advance("rendering the field with the reference TF");
  Image before_img = composite_over(field_renderer.render(field_ref_tf_map, ref_tf, s), s.background);
  advance("rendering the field with the optimized TF");
  Image after_img = composite_over(field_renderer.render(field_opt_tf_map, opt_tf, s), s.background);
  out.before = compare_images(ref_img, before_img);
  out.after = compare_images(ref_img, after_img);
  // Pictures of almost nothing agree well whatever the TF: say so where the metrics are read
  // (the ERA5 correlation recipe's PSNR rose 25.6 -> 38.5 dB between two near-white pictures).
  {
    std::vector<std::string> empty;
    const std::pair<const char*, const Image*> pictures[] = {
        {"the reference", &ref_img}, {"the field with the reference TF", &before_img},
        {"the field with the optimized TF", &after_img}};
    std::ostringstream os;
    for (const auto& [name, img] : pictures)
      if (const double f = background_fraction(*img, s.background); f > kNearlyEmptyFraction) {
        os.str("");
        os << name << " (" << std::lround(100 * f) << " %)";
        empty.push_back(os.str());
      }
    if (!empty.empty()) {
      os.str("");
      os << "nearly empty renderings: background, or colour too faint to tell from it, covers ";
      for (size_t k = 0; k < empty.size(); ++k) os << (k ? k + 1 == empty.size() ? " and " : ", " : "") << empty[k];
      os << " of the picture, so the image metrics compare mostly background; a larger --opacity-scale (now "
         << s.opacity_scale << "), a TF with more opacity or another camera shows the fields";
      out.warnings.push_back(os.str());
    }
  }
  // The pictures show the markers and the box outline; the metrics above were taken without them.
  for (Image* img : {&ref_img, &before_img, &after_img}) {
    draw_box_outline(*img, geometry, s, &in.ref.axes, in.markers);
    draw_markers(*img, geometry, s, in.markers);
  }
  save("reference.png", ref_img);
  save("field_reference_tf.png", before_img);
  save("field_optimized_tf.png", after_img);

  advance("residual maps");
  const Volume res_before = residual_map_gpu(ctx, in.ref, ref, field, ref_map, field_ref_tf_map, ref_tf, ref_tf);
  const Volume res_after = residual_map_gpu(ctx, in.ref, ref, field, ref_map, field_opt_tf_map, ref_tf, opt_tf);
  out.residual_max_before = max_value(res_before);
  out.residual_max_after = max_value(res_after);
  if (!in.changed_regions.empty()) {
    out.residual_inside_before = fraction_inside(res_before, in.changed_regions);
    out.residual_inside_after = fraction_inside(res_after, in.changed_regions);
  }
  // One display range for both, so the two pictures are comparable.
  const FieldRange res_range = residual_display_range({&res_before, &res_after});
  const TransferFunction res_tf = residual_transfer_function();
  advance("rendering residual maps");
  Buffer res_tf_buf = upload_tf(ctx, res_tf, "report: residual TF");
  const FieldMapping res_map = make_mapping(res_range, uint32_t(res_tf.size()));
  Image res_imgs[2];
  for (int k = 0; k < 2; ++k) {
    const DeviceField res = field_over_host_values(ctx, (k == 0 ? res_before : res_after).values, "report: residual map");
    res_imgs[k] = composite_over(GpuRenderer(ctx, res, geometry).render(res_map, res_tf_buf, s), s.background);
    draw_box_outline(res_imgs[k], geometry, s, &in.ref.axes, in.markers);
    draw_markers(res_imgs[k], geometry, s, in.markers);
  }
  save("residual_reference_tf.png", res_imgs[0]);
  save("residual_optimized_tf.png", res_imgs[1]);

  advance("slices");
  write_slices(in, res_after, res_tf, res_range, out, save);

  advance("TF plots");
  TfPlotOptions plot;
  plot.width = std::max<uint32_t>(s.width, 320);
  plot.log_counts = in.histogram_log;
  plot.title = "Reference TF, reference field histogram";
  plot.axis_label = field_label(in.ref);
  const Image plot_ref = plot_transfer_function(in.ref_tf, in.ref.values, r.ref_range, plot);
  plot.title = "Reference TF, field histogram";
  plot.axis_label = field_label(in.field);
  const Image plot_before = plot_transfer_function(in.ref_tf, in.field.values, r.field_range, plot);
  plot.title = "Optimized TF, field histogram";
  const Image plot_opt = plot_transfer_function(r.tf, in.field.values, r.field_range, plot);
  plot.title = "Residual TF, histogram after";
  plot.axis_label = kResidualValueLabel;
  const Image plot_res = plot_transfer_function(res_tf, res_after.values, res_range, plot);
  save("tf_reference.png", plot_ref);
  save("tf_field_reference.png", plot_before);
  save("tf_optimized.png", plot_opt);
  save("tf_residual.png", plot_res);
  for (const ReportFigure& f : in.extra_figures) save(f.file, f.image);

  advance("overview");
  const Image overview = stack_rows(
      {compose_panels({{ref_img, "Reference"}, {before_img, "Field, reference TF"}, {after_img, "Field, optimized TF"}}, 3),
       compose_panels({{plot_ref, ""}, {plot_before, ""}, {plot_opt, ""}}, 3),
       compose_panels({{metrics_panel(out, r, s.width, s.height), "Metrics"},
                       {res_imgs[0], "Residual, reference TF"},
                       {res_imgs[1], "Residual, optimized TF"}},
                      3)},
      {255, 255, 255});
  save("overview.png", overview);

  pngs.finish();

  advance("metrics.json");
  nlohmann::json metrics;
  metrics["images"] = {{"reference_tf", out.before.to_json()}, {"optimized_tf", out.after.to_json()}};
  metrics["voxels"] = {{"rmse_reference_tf", r.before.rmse()}, {"rmse_optimized_tf", r.after.rmse()},
                       {"mae_reference_tf", r.before.mae()},   {"mae_optimized_tf", r.after.mae()},
                       {"voxels_with_data", r.after.voxels}};
  metrics["residual"] = {{"max_reference_tf", out.residual_max_before},
                         {"max_optimized_tf", out.residual_max_after},
                         {"display_range", {res_range.lo, res_range.hi}}};
  if (out.residual_inside_before && out.residual_inside_after)
    metrics["residual"]["fraction_inside_changed_regions"] = {{"reference_tf", *out.residual_inside_before},
                                                              {"optimized_tf", *out.residual_inside_after}};
  metrics["render_settings"] = settings_json(s);
  metrics["histogram"] = in.histogram_log ? "log" : "linear";
  metrics["made"] = report_made(ctx);
  if (!out.warnings.empty()) metrics["report_warnings"] = out.warnings;
  metrics["font"] = font.empty() ? "built-in 5x7 bitmap (DejaVu Sans not found)" : font;
  if (!in.command_line.empty()) metrics["command_line"] = in.command_line;
  if (!in.version.empty()) metrics["version"] = in.version;
  metrics["optimize"] = to_json(r);
  metrics["fields"] = {{"reference", in.ref.name}, {"field", in.field.name}, {"dims", in.ref.dims}};
  if (!in.markers.empty()) metrics["markers"] = in.markers;
  metrics["slices"] = {{"point", out.slice_point}, {"files", nlohmann::json::array()}};
  for (const auto& sl : out.slices) metrics["slices"]["files"].push_back({{"file", sl.file}, {"plane", sl.caption}});
  if (!in.extra_metrics.is_null()) metrics["extra"] = in.extra_metrics;
  write_file_atomically(dir / "metrics.json", json_text(metrics, 2) + "\n");
  out.files.push_back("metrics.json");

  // What reproduces the page: where and what was run (its paths may be relative to that
  // directory), the version, and both TFs as used (linear tables).
  write_file_atomically(dir / "command.txt",
                        (in.command_line.empty() ? std::string("(library call)")
                                                 : "cd " + shell_word(std::filesystem::current_path().string()) + "\n" +
                                                       in.command_line) +
                            "\n" + (in.version.empty() ? "" : in.version + "\n"));
  write_file_atomically(dir / "reference_tf.json", tf_to_json(in.ref_tf));
  write_file_atomically(dir / "optimized_tf.json", tf_to_json(r.tf));
  for (const char* f : {"command.txt", "reference_tf.json", "optimized_tf.json"}) out.files.push_back(f);
  if (!in.inputs.is_null()) {
    write_file_atomically(dir / "inputs.json", json_text(in.inputs, 2) + "\n");
    out.files.push_back("inputs.json");
  }

  advance("index.html");
  write_file_atomically(dir / "index.html", report_html(in, out, metrics));
  out.files.push_back("index.html");
  out.index = final_dir / "index.html";
  if (dir == final_dir) remove_earlier_report_files(batch, dir, out.files);  // an existing directory
  batch.commit();
  progress.finish();
  return out;
}

}  // namespace tfm
