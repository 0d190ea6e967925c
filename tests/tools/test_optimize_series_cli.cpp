// `tfmatch optimize` with several fields, as a user runs it: a time range, several files and a
// pattern expand to one TF file per field, each the same bytes as that field's own run; one
// shared TF with --shared-tf; the series table; the refusals (mixed grids naming the field, a
// pattern matching nothing, what a series does not do yet) write nothing. On the shared ERA5
// ensemble: ten members, one TF each and one for all.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "cli_runner.h"
#include "slab_test_files.h"
#include "tfmatch/io/json.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::run_cli;

using test::read_text;

class OptimizeSeriesCli : public ::testing::Test {
 protected:
  void SetUp() override {
    ref = slab_test::write_raw(dir.path(), "ref", slab_test::test_field({19, 13, 9}, 0)).string();
    nc = slab_test::write_netcdf(dir.path(), "field", slab_test::test_field({19, 13, 9}, 3)).string();
    fs::create_directory(dir / "runs");
    for (int k = 0; k < 3; ++k)
      steps.push_back(
          slab_test::write_raw(dir / "runs", "step" + std::to_string(k), slab_test::test_field({19, 13, 9}, 4 + k)).string());
    other_grid = slab_test::write_raw(dir.path(), "other", slab_test::test_field({19, 13, 8}, 1)).string();
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
  }
  std::string base(const std::string& out) const {
    return "optimize --ref " + ref + " --ref-tf " + (dir / "tf.json").string() + " --tf-size 24 --out " +
           (dir / out).string();
  }
  formats_test::TempDir dir;
  std::string ref, nc, other_grid;
  std::vector<std::string> steps;  // the raw files runs/step<k>_19x13x9_float32.raw
};

// A report directory used again holds one run's report: a series after a single field's report
// removes that report's files (its metrics.json and command.txt described the other run), a
// single report after a series the series' files; the user's own files there are kept.
TEST_F(OptimizeSeriesCli, AReportDirectoryUsedAgainHoldsOneRunsReport) {
  const fs::path rep = dir / "rep";
  fs::create_directory(rep);
  std::ofstream(rep / "my-notes.txt") << "mine";
  const std::string small = " --width 48 --height 40";
  auto r = run_cli(base("one.json") + " --field " + steps[0] + " --report " + rep.string() + small);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(rep / "command.txt"));
  ASSERT_TRUE(fs::exists(rep / "metrics.json"));
  r = run_cli(base("many.json") + " --field " + steps[0] + " --field " + steps[1] + " --field " + steps[2] +
              " --report " + rep.string() + small);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(rep)) names.insert(e.path().filename().string());
  for (const char* gone : {"command.txt", "metrics.json", "overview.png", "slices_z.png", "optimized_tf.json",
                           "residual_optimized_tf.png"})
    EXPECT_FALSE(names.count(gone)) << gone << " of the first run is still there";
  for (const char* there : {"index.html", "series.json", "field_002.png", "my-notes.txt"}) EXPECT_TRUE(names.count(there)) << there;
  EXPECT_NE(read_text(rep / "index.html").find("step2"), std::string::npos);
  // Back to one field: the series' files go, three fields' pictures among them.
  r = run_cli(base("one.json") + " --field " + steps[1] + " --report " + rep.string() + small);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  names.clear();
  for (const auto& e : fs::directory_iterator(rep)) names.insert(e.path().filename().string());
  for (const char* gone : {"series.json", "field_000.png", "field_002_tf_before.png", "rmse.png"})
    EXPECT_FALSE(names.count(gone)) << gone;
  for (const char* there : {"command.txt", "metrics.json", "index.html", "my-notes.txt"}) EXPECT_TRUE(names.count(there)) << there;
  EXPECT_NE(read_text(rep / "command.txt").find("step1"), std::string::npos);
}

TEST_F(OptimizeSeriesCli, OneTfPerFieldEachAsItsOwnRun) {
  // Two time steps of a NetCDF file and three raw files by pattern: five fields.
  const std::string pattern = "'" + (dir / "runs" / "step*.raw").string() + "'";
  const auto r = run_cli(base("tf.json") + " --field " + nc + ":T,time=0..1 --field " + pattern + " --json " +
                         (dir / "series.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = nlohmann::json::parse(read_text(dir / "series.json"));
  ASSERT_EQ(j["fields"].size(), 5u);
  EXPECT_FALSE(j["shared_tf"].get<bool>());
  const std::vector<std::string> specs = {nc + ":T,time=0", nc + ":T,time=1", steps[0], steps[1], steps[2]};
  for (size_t i = 0; i < specs.size(); ++i) {
    SCOPED_TRACE(specs[i]);
    EXPECT_EQ(j["fields"][i]["field"], specs[i]);
    const fs::path tf_file = dir / ("tf_00" + std::to_string(i) + ".json");
    ASSERT_TRUE(fs::exists(tf_file));
    EXPECT_LT(j["fields"][i]["voxel_rmse_after"].get<double>(), j["fields"][i]["voxel_rmse_before"].get<double>());
    const auto one = run_cli(base("one.json") + " --field " + specs[i]);
    ASSERT_EQ(one.exit_code, 0) << one.output;
    EXPECT_EQ(read_text(tf_file), read_text(dir / "one.json")) << "the same TF as the field's own run";
  }
  const std::string csv = read_text(dir / "tf_series.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 6) << csv;
  EXPECT_NE(csv.find("index,field,tf_file,field_lo,field_hi,voxels,voxel_rmse_before,voxel_rmse_after"), std::string::npos);
}

// The keys docs/commands.md's tables under "The JSON summary" list after `<!-- json-keys: NAME -->`
// (each row's backticked names in its first cell), in a set.
std::set<std::string> documented_keys(const std::string& name) {
  std::ifstream in(std::string(TFMATCH_SOURCE_DIR) + "/docs/commands.md");
  std::set<std::string> keys;
  bool inside = false;
  for (std::string line; std::getline(in, line);) {
    if (line == "<!-- json-keys: " + name + " -->") {
      inside = true;
      continue;
    }
    if (!inside) continue;
    if (line.empty()) break;
    if (line.rfind("| `", 0) != 0) continue;  // the header and its rule
    const std::string cell = line.substr(1, line.find('|', 1) - 1);
    for (size_t a = cell.find('`'); a != std::string::npos; a = cell.find('`', cell.find('`', a + 1) + 1))
      keys.insert(cell.substr(a + 1, cell.find('`', a + 1) - a - 1));
  }
  EXPECT_FALSE(keys.empty()) << "no table after <!-- json-keys: " << name << " --> in docs/commands.md";
  return keys;
}

std::set<std::string> keys_of(const nlohmann::json& j) {
  std::set<std::string> keys;
  for (const auto& [k, v] : j.items()) keys.insert(k);
  return keys;
}

// optimize's --json, of one field and of a series (with and without one shared TF), has exactly
// the keys its documentation lists: single and series runs name the same numbers alike.
TEST_F(OptimizeSeriesCli, JsonKeysAreTheDocumentedOnes) {
  ASSERT_EQ(run_cli(base("one.json") + " --field " + steps[0] + " --json " + (dir / "one_run.json").string()).exit_code, 0);
  EXPECT_EQ(keys_of(nlohmann::json::parse(read_text(dir / "one_run.json"))), documented_keys("optimize"));
  for (const std::string shared : {"", " --shared-tf"}) {
    SCOPED_TRACE(shared);
    const auto r = run_cli(base("s.json") + " --field " + steps[0] + " --field " + steps[1] + shared + " --json " +
                           (dir / "series_run.json").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const nlohmann::json j = nlohmann::json::parse(read_text(dir / "series_run.json"));
    std::set<std::string> want = documented_keys("optimize-series");
    if (shared.empty()) want.erase("details");  // with --shared-tf only
    EXPECT_EQ(keys_of(j), want);
    ASSERT_EQ(j["fields"].size(), 2u);
    for (const auto& row : j["fields"]) EXPECT_EQ(keys_of(row), documented_keys("optimize-series-field"));
  }
}

// Each row names the field as loaded: a time chosen by the global --time shows in the table, the
// report's labels and the printed summary, not only in the JSON's "name".
TEST_F(OptimizeSeriesCli, RowsNameTheTimeTheGlobalSelectionChose) {
  const auto r = run_cli("optimize --ref " + nc + ":T --ref-tf " + (dir / "tf.json").string() + " --tf-size 24 --out " +
                         (dir / "t.json").string() + " --field " + nc + ":T --field " + nc + ":T,time=0 --time 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string csv = read_text(dir / "t_series.csv");
  EXPECT_NE(csv.find("0,\"" + nc + ":T,time=1\""), std::string::npos) << csv;
  EXPECT_NE(csv.find("1,\"" + nc + ":T,time=0\""), std::string::npos) << csv;
  EXPECT_NE(r.output.find(fs::path(nc).filename().string() + ":T,time=1"), std::string::npos) << r.output;
}

TEST_F(OptimizeSeriesCli, SharedTfForAllFields) {
  const auto r = run_cli(base("shared.json") + " --field " + nc + ":T,time=0..1 --field " + steps[0] +
                         " --shared-tf --solver qp");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("one shared TF"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(dir / "shared.json"));
  EXPECT_FALSE(fs::exists(dir / "shared_000.json"));
  const std::string csv = read_text(dir / "shared_series.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 4) << csv;
}

// Each field streamed slab by slab: the same TF files as the fields loaded whole.
TEST_F(OptimizeSeriesCli, StreamedSeriesWritesTheSameTfs) {
  for (const char* shared : {"", " --shared-tf"}) {
    SCOPED_TRACE(shared);
    const std::string fields = " --field " + nc + ":T,time=0..1 --field " + steps[1] + shared;
    auto on = run_cli(base("on.json") + fields + " --stream on");
    ASSERT_EQ(on.exit_code, 0) << on.output;
    auto off = run_cli(base("off.json") + fields + " --stream off");
    ASSERT_EQ(off.exit_code, 0) << off.output;
    // Each file written (read_text gives "" for a missing one, and two missing files are equal).
    const auto same = [&](const std::string& a, const std::string& b) {
      const std::string on_text = read_text(dir / a), off_text = read_text(dir / b);
      EXPECT_NE(on_text.find("\"rgba\""), std::string::npos) << a << ": " << on_text;
      EXPECT_EQ(on_text, off_text) << a << " and " << b;
    };
    if (*shared) {
      same("on.json", "off.json");
    } else {
      for (const char* suffix : {"_000.json", "_001.json", "_002.json"}) same(std::string("on") + suffix, std::string("off") + suffix);
    }
  }
  auto r = run_cli(base("x.json") + " --field " + nc + ":T,time=0..1 --stream on --solver cgls");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("normal-equations and qp"), std::string::npos) << r.output;
}

TEST_F(OptimizeSeriesCli, ReportShowsEveryFieldAndTheSeries) {
  const auto r = run_cli(base("tf.json") + " --field " + nc + ":T,time=0..1 --field " + steps[0] + " --report " +
                         (dir / "rep").string() + " --width 48 --height 40");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* f : {"index.html", "series.json", "reference.png", "rmse.png", "psnr.png", "tfs.png", "field_000.png",
                        "field_000_before.png", "field_002.png", "tf_reference.png", "field_002_tf_before.png",
                        "field_002_tf.png"})
    EXPECT_TRUE(fs::exists(dir / "rep" / f)) << f;
  const nlohmann::json m = nlohmann::json::parse(read_text(dir / "rep" / "series.json"));
  ASSERT_EQ(m["fields"].size(), 3u);
  for (const auto& f : m["fields"]) {
    EXPECT_LT(f["voxel_rmse_after"].get<double>(), f["voxel_rmse_before"].get<double>());
    EXPECT_TRUE(f["image_after"]["psnr"].is_number() || f["image_after"]["psnr"] == "inf");
  }
  const std::string html = read_text(dir / "rep" / "index.html");
  EXPECT_NE(html.find("field_002.png"), std::string::npos);
  EXPECT_NE(html.find("one TF per field"), std::string::npos);
  EXPECT_EQ(html.find("No PSNR plot"), std::string::npos);
  // SSIM before beside after, and the page's numbers linked.
  EXPECT_NE(html.find("<th>SSIM before</th><th>after</th>"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"series.json\">"), std::string::npos);
  // Each field's row holds the reference beside it, and the TF plots beneath.
  size_t rows = 0;
  for (size_t at = html.find("src=\"reference.png\""); at != std::string::npos; at = html.find("src=\"reference.png\"", at + 1))
    ++rows;
  EXPECT_EQ(rows, 3u);
  const size_t row2 = html.find("<h3>2: ");
  ASSERT_NE(row2, std::string::npos);
  EXPECT_LT(html.find("src=\"reference.png\"", row2), html.find("src=\"field_002_before.png\"", row2));
  EXPECT_LT(html.find("src=\"field_002.png\"", row2), html.find("src=\"field_002_tf.png\"", row2));
}

// A field given twice is fitted twice, with a warning naming both places ("field k of n").
TEST_F(OptimizeSeriesCli, AFieldGivenTwiceIsNamed) {
  const std::string pattern = "'" + (dir / "runs" / "step*.raw").string() + "'";
  const auto r = run_cli(base("tf.json") + " --field " + pattern + " --field " + steps[1] + " --json " +
                         (dir / "twice.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = nlohmann::json::parse(read_text(dir / "twice.json"));
  ASSERT_EQ(j["fields"].size(), 4u);
  ASSERT_EQ(j["warnings"].size(), 1u) << j.dump();
  EXPECT_EQ(j["warnings"][0], "field 4 of 4 is field 2 again (" + steps[1] + "): it is fitted twice");
  EXPECT_NE(r.output.find("warning: field 4 of 4 is field 2 again"), std::string::npos) << r.output;
}

// Each field's warnings are on the series page, named by field, as the summary prints them (here
// a field range that leaves part of every field outside).
TEST_F(OptimizeSeriesCli, ReportShowsEachFieldsWarnings) {
  const auto r = run_cli(base("tf.json") + " --field " + steps[0] + " --field " + steps[1] + " --field-range 300,360" +
                         " --report " + (dir / "rep").string() + " --width 32 --height 24");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string html = read_text(dir / "rep" / "index.html");
  for (int i : {0, 1}) {
    const std::string label = std::to_string(i) + ": " + fs::path(steps[size_t(i)]).filename().string() + ": ";
    const size_t at = html.find("<div class=\"warn\">" + label);
    ASSERT_NE(at, std::string::npos) << label << "\n" << html;
    EXPECT_NE(html.find("outside the given field range", at), std::string::npos) << html;
  }
}

TEST_F(OptimizeSeriesCli, RefusalsNameTheProblemAndWriteNothing) {
  auto r = run_cli(base("x.json") + " --field " + nc + ":T,time=0 --field " + other_grid);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("field 2 of 2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("other"), std::string::npos) << r.output;
  r = run_cli(base("x.json") + " --field '" + (dir / "nothing*.raw").string() + "'");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("matches no file"), std::string::npos) << r.output;
  r = run_cli(base("x.json") + " --field " + nc + ":T,time=0..1 --report " + (dir / "rep").string() + " --marker 1,1,1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("report of one field"), std::string::npos) << r.output;
  r = run_cli(base("x.json") + " --field " + nc + ":T,time=0..1 --shared-tf --solver cgls");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("normal-equations or qp"), std::string::npos) << r.output;
  r = run_cli(base("x.json") + " --field " + nc + ":T,time=0 --shared-tf");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("several --field"), std::string::npos) << r.output;
  for (const char* name : {"x.json", "x_000.json", "x_series.csv"}) EXPECT_FALSE(fs::exists(dir / name)) << name;
}

TEST_F(OptimizeSeriesCli, Era5MembersOneTfEachAndOneForAll) {
  const std::string data = test::shared_data_dir();
  if (data.empty()) GTEST_SKIP() << "no ../shared/data";
  const std::string grib = data + "/era5_ensemble_grib1/era5-levels-members.grib";
  const std::string ref_spec = grib + ":z,member=0";
  auto r = run_cli("optimize --ref " + ref_spec + " --ref-tf viridis --field " + grib + ":t,member=0..9 --out " +
                   (dir / "t.json").string() + " --json " + (dir / "t.summary.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json each = nlohmann::json::parse(read_text(dir / "t.summary.json"));
  ASSERT_EQ(each["fields"].size(), 10u);
  EXPECT_TRUE(fs::exists(dir / "t_009.json"));
  r = run_cli("optimize --ref " + ref_spec + " --ref-tf viridis --field " + grib + ":t,member=0..9 --shared-tf --out " +
              (dir / "t_all.json").string() + " --json " + (dir / "t_all.summary.json").string() + " --report " +
              (dir / "t_all_report").string() + " --width 96 --height 48");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json report = nlohmann::json::parse(read_text(dir / "t_all_report" / "series.json"));
  ASSERT_EQ(report["fields"].size(), 10u);
  for (const auto& f : report["fields"])  // the members' maps look like the geopotential's under the one TF
    EXPECT_GT(f["image_after"]["psnr"].get<double>(), f["image_before"]["psnr"].get<double>() + 5.0) << f.dump();
  const nlohmann::json all = nlohmann::json::parse(read_text(dir / "t_all.summary.json"));
  // Ten members of one forecast: one TF (over the union of their ranges) fits them all about as
  // well as ten do (each over its own range).
  for (size_t m = 0; m < 10; ++m) {
    const double own = each["fields"][m]["voxel_rmse_after"].get<double>(), shared = all["fields"][m]["voxel_rmse_after"].get<double>();
    EXPECT_LT(std::abs(shared - own), 0.1 * own) << "member " << m;
    EXPECT_LT(shared, 0.6 * all["fields"][m]["voxel_rmse_before"].get<double>());
  }
}

}  // namespace
}  // namespace tfm
