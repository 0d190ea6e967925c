// The optimization report: every picture and file written, metrics.json consistent with the
// PNGs on disk, the optimized TF moving the images closer on the demo pair, and a page that
// references every picture.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/model/shell_words.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/report/report.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using test::read_text;

class Report : public test::GpuTest {};

TEST_F(Report, WritesPicturesMetricsAndPage) {
  test::TempDir dir;
  const Volume ref = synthetic_reference(20, 18, 16);
  const Volume field = synthetic_remapped(ref);
  const TransferFunction ref_tf = demo_transfer_function(32);
  OptimizeRequest req;
  req.ref = &ref;
  req.field = &field;
  req.ref_tf = ref_tf;
  req.tf_size = 32;
  OptimizeResult result = run_optimize(ctx(), req);
  result.warnings.push_back("cond(M) <test warning>");

  ReportInputs in{ref, field, ref_tf, result, RenderSettings{}};
  in.settings.width = 48;
  in.settings.height = 40;
  in.settings.box_outline = false;  // so that the PNGs on disk are the pictures measured
  in.title = "test <report>";
  in.command_line = "tfmatch optimize --ref 'a b.nc:T' --out x.json";
  in.version = "tfmatch 9.9.9 (commit test)";
  in.histogram_log = false;
  in.extra_figures.push_back({"Loss", "loss.png", Image(20, 10, {0, 0, 255}), "a curve"});
  const ReportSummary s = write_report(ctx(), in, dir.path);
  // Every file written is one report_file_names() lists (the output plan of the commands relies
  // on it), and the directory holds those files only: no temporary file is left.
  const std::vector<std::string> names = report_file_names();
  for (const std::string& f : s.files) EXPECT_NE(std::find(names.begin(), names.end(), f), names.end()) << f;
  EXPECT_EQ(size_t(std::distance(std::filesystem::directory_iterator(dir.path), std::filesystem::directory_iterator{})),
            s.files.size());

  for (const char* name : {"reference.png", "field_reference_tf.png", "field_optimized_tf.png",
                           "residual_reference_tf.png", "residual_optimized_tf.png"}) {
    const Image img = read_png(dir / name);
    EXPECT_EQ(img.width, 48u) << name;
    EXPECT_EQ(img.height, 40u) << name;
  }
  for (const char* name : {"tf_reference.png", "tf_field_reference.png", "tf_optimized.png", "tf_residual.png",
                           "overview.png", "loss.png"})
    EXPECT_NO_THROW(read_png(dir / name)) << name;

  // metrics.json holds what the PNGs on disk give.
  const auto m = nlohmann::json::parse(read_text(dir / "metrics.json"));
  const Image ref_img = read_png(dir / "reference.png");
  const ImageMetrics before = compare_images(ref_img, read_png(dir / "field_reference_tf.png"));
  const ImageMetrics after = compare_images(ref_img, read_png(dir / "field_optimized_tf.png"));
  EXPECT_DOUBLE_EQ(m["images"]["reference_tf"]["rmse"].get<double>(), before.rmse);
  EXPECT_DOUBLE_EQ(m["images"]["optimized_tf"]["ssim"].get<double>(), after.ssim);
  EXPECT_DOUBLE_EQ(m["voxels"]["rmse_optimized_tf"].get<double>(), result.after.rmse());
  EXPECT_EQ(m["render_settings"]["width"], 48);
  // On the demo pair the optimized TF brings both the voxels and the images closer.
  EXPECT_LT(after.rmse, before.rmse);
  EXPECT_GT(after.ssim, before.ssim);
  EXPECT_LT(s.residual_max_after, s.residual_max_before + 1e-6);

  const std::string html = read_text(s.index);
  for (const std::string& f : s.files)
    if (f.ends_with(".png") && f != "overview.png") EXPECT_NE(html.find("src=\"" + f + "\""), std::string::npos) << f;
  EXPECT_NE(html.find("test &lt;report&gt;"), std::string::npos) << "title is escaped";
  EXPECT_NE(html.find("LPIPS"), std::string::npos);
  // Warnings on the page; what reproduces it saved beside it; the histogram scale named.
  EXPECT_NE(html.find("cond(M) &lt;test warning&gt;"), std::string::npos);
  EXPECT_NE(html.find("tfmatch optimize --ref 'a b.nc:T' --out x.json"), std::string::npos) << html;
  EXPECT_NE(html.find("tfmatch 9.9.9 (commit test)"), std::string::npos);
  EXPECT_NE(html.find("histograms linear counts"), std::string::npos);
  // An after cell is marked better only past 1 % of the larger value (1.213 -> 1.212 was marked).
  const auto row = [&](const std::string& name) {
    const size_t at = html.find("<tr><td>" + name + "</td>");
    return at == std::string::npos ? std::string() : html.substr(at, html.find("</tr>", at) - at);
  };
  ASSERT_FALSE(row("Residual max").empty()) << html;
  const bool rmse_better = after.rmse < before.rmse - 0.01 * std::max(before.rmse, after.rmse);
  EXPECT_EQ(row("Image RMSE (0&ndash;255)").find("class=\"better\"") != std::string::npos, rmse_better)
      << row("Image RMSE (0&ndash;255)");
  const double rb = s.residual_max_before, ra = s.residual_max_after;
  EXPECT_EQ(row("Residual max").find("class=\"better\"") != std::string::npos, ra < rb - 0.01 * std::max(rb, ra))
      << row("Residual max");
  // Where it ran first: the command's paths may be relative to it.
  EXPECT_EQ(read_text(dir / "command.txt"),
            "cd " + shell_word(std::filesystem::current_path().string()) + "\n" + in.command_line + "\n" + in.version + "\n");
  EXPECT_EQ(read_transfer_function(dir / "reference_tf.json").rgba, ref_tf.rgba);
  const TransferFunction saved = read_transfer_function(dir / "optimized_tf.json");
  EXPECT_EQ(saved.rgba, result.tf.rgba);
  ASSERT_TRUE(saved.range);
  EXPECT_EQ(saved.range->lo, result.field_range.lo);
  EXPECT_EQ(m["histogram"], "linear");
  // When and where, on the page and in the JSON: the date, the device, the driver.
  EXPECT_EQ(m["made"]["device"], ctx().device_name());
  EXPECT_EQ(m["made"]["driver"], ctx().driver_description());
  EXPECT_NE(ctx().driver_description().find(", Vulkan 1."), std::string::npos) << ctx().driver_description();
  EXPECT_EQ(m["made"]["time_utc"].get<std::string>().size(), std::string("2026-12-07 13:05 UTC").size());
  EXPECT_NE(html.find(report_made_text(m["made"])), std::string::npos);
  EXPECT_EQ(m["command_line"], in.command_line);

  // Slices through the middle, one picture per axis, four panels each, on the page.
  ASSERT_EQ(s.slices.size(), 3u);
  EXPECT_EQ(s.slice_point, (GridIndex{10, 9, 8}));
  EXPECT_EQ(s.slices[0].file, "slices_z.png");
  EXPECT_EQ(s.slices[0].caption, "z = 8");
  for (const auto& sl : s.slices) {
    const Image img = read_png(dir / sl.file);
    EXPECT_GT(img.width, 3 * img.height) << sl.file;  // four panels side by side
    EXPECT_NE(html.find(sl.caption), std::string::npos) << sl.caption;
  }
  EXPECT_EQ(m["slices"]["point"], nlohmann::json({10, 9, 8}));
}

TEST_F(Report, SlicesGoThroughTheChosenPointAndSkipLines) {
  test::TempDir dir;
  const Volume ref3 = synthetic_reference(12, 10, 1);  // one level: only the z plane is a plane
  const Volume field3 = synthetic_remapped(ref3);
  const TransferFunction ref_tf = demo_transfer_function(16);
  OptimizeRequest req;
  req.ref = &ref3;
  req.field = &field3;
  req.ref_tf = ref_tf;
  req.tf_size = 16;
  const OptimizeResult result = run_optimize(ctx(), req);
  ReportInputs in{ref3, field3, ref_tf, result, RenderSettings{}};
  in.settings.width = 32;
  in.settings.height = 32;
  in.slice_point = GridIndex{3, 7, 0};
  const ReportSummary s = write_report(ctx(), in, dir.path);
  ASSERT_EQ(s.slices.size(), 1u);
  EXPECT_EQ(s.slices[0].file, "slices_z.png");
  EXPECT_FALSE(std::filesystem::exists(dir / "slices_x.png"));
  in.slice_point = GridIndex{3, 10, 0};  // y outside the grid: refused before anything is written
  test::TempDir other;
  EXPECT_THROW(write_report(ctx(), in, other.path / "r"), std::runtime_error);
  EXPECT_FALSE(std::filesystem::exists(other.path / "r"));
}

TEST_F(Report, PicturesCarryTheBoxOutline) {
  test::TempDir dir;
  const Volume ref = synthetic_reference(10, 9, 8);
  const Volume field = synthetic_remapped(ref);
  OptimizeRequest req;
  req.ref = &ref;
  req.field = &field;
  req.ref_tf = demo_transfer_function(16);
  req.tf_size = 16;
  const OptimizeResult result = run_optimize(ctx(), req);
  ReportInputs in{ref, field, req.ref_tf, result, RenderSettings{}};
  in.settings.width = in.settings.height = 40;
  const ReportSummary s = write_report(ctx(), in, dir.path);
  // The outline is on by default: grey box edges on the picture written.
  const auto m = nlohmann::json::parse(read_text(dir / "metrics.json"));
  EXPECT_EQ(m["render_settings"]["box_outline"], true);
  const Image img = read_png(dir / "reference.png");
  size_t grey = 0;
  for (uint32_t y = 0; y < img.height; ++y)
    for (uint32_t x = 0; x < img.width; ++x) {
      const uint8_t* p = img.at(x, y);
      grey += p[0] == p[1] && p[1] == p[2] && p[0] > 100 && p[0] < 200;
    }
  EXPECT_GT(grey, 20u) << "outline pixels";
  EXPECT_FALSE(s.files.empty());
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];  // the demo pair shows its colours

  // Nearly no opacity: pictures of the background, whose metrics agree whatever the TF. Said on
  // the page and in metrics.json, with the fraction and the way out.
  in.settings.opacity_scale = 0.01;
  test::TempDir faint;
  const ReportSummary f = write_report(ctx(), in, faint.path);
  ASSERT_EQ(f.warnings.size(), 1u);
  EXPECT_NE(f.warnings[0].find("nearly empty renderings: background, or colour too faint to tell from it, covers the reference ("), std::string::npos)
      << f.warnings[0];
  EXPECT_NE(f.warnings[0].find("--opacity-scale (now 0.01)"), std::string::npos) << f.warnings[0];
  // The fraction on a picture: a white one is all background, a black one none of it.
  EXPECT_EQ(background_fraction(Image(4, 3, {255, 255, 255}), {1.0, 1.0, 1.0}), 1.0);
  EXPECT_EQ(background_fraction(Image(4, 3, {0, 0, 0}), {1.0, 1.0, 1.0}), 0.0);
  EXPECT_EQ(background_fraction(Image(4, 3, {239, 239, 255}), {1.0, 1.0, 1.0}), 1.0);  // faint haze
  EXPECT_EQ(background_fraction(Image(4, 3, {238, 255, 255}), {1.0, 1.0, 1.0}), 0.0);
  EXPECT_NE(read_text(faint / "index.html").find("nearly empty renderings"), std::string::npos);
  EXPECT_EQ(nlohmann::json::parse(read_text(faint / "metrics.json"))["report_warnings"][0], f.warnings[0]);
}

TEST_F(Report, RejectsFieldsOnDifferentGrids) {
  test::TempDir dir;
  const Volume ref = synthetic_reference(8, 8, 8);
  const Volume other = synthetic_reference(8, 8, 9);
  OptimizeResult r;
  r.tf = demo_transfer_function(8);
  EXPECT_THROW(write_report(ctx(), {ref, other, r.tf, r, RenderSettings{}}, dir.path), std::runtime_error);
}

}  // namespace
}  // namespace tfm
