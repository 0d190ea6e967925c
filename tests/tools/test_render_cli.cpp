// The rendering commands run as a user runs them: render, residual, metrics, bench-render,
// demo and optimize with --report, and their errors.
#include <fstream>

#include <gtest/gtest.h>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/model/color_bar.h"
#include "tfmatch/report/png_io.h"

namespace tfm {
namespace {

using test::run_cli;
using test::TempDir;
using test::write_floats;

class RenderCli : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<float> a(6 * 5 * 4), b(a.size());
    for (size_t i = 0; i < a.size(); ++i) {
      a[i] = float(i % 13) / 12.0f;
      b[i] = 10.0f - 4.0f * a[i];
    }
    write_floats(dir / "a_6x5x4_float32.raw", a);
    write_floats(dir / "b_6x5x4_float32.raw", b);
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,1,0.1],[0,1,0,0.6],[1,0,0,0.9]]})";
    std::ofstream(dir / "clear.json") << R"({"rgba": [[1,1,1,0],[1,1,1,0]]})";
  }
  TempDir dir;
};

TEST_F(RenderCli, RenderWritesAPngOfTheRequestedSize) {
  auto r = run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json" + " --out " +
                   dir / "a.png" + " --width 31 --height 17 --elevation 90 --azimuth 10");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image img = read_png(dir / "a.png");
  EXPECT_EQ(img.width, 31u);
  EXPECT_EQ(img.height, 17u);
  // A transparent TF over a black background is black everywhere without the box outline, and
  // shows the grey outline with it (the default).
  r = run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "clear.json" + " --out " +
              dir / "c.png" + " --width 8 --height 8 --background black --no-outline");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (uint8_t v : read_png(dir / "c.png").rgb) ASSERT_EQ(v, 0);
  r = run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "clear.json" + " --out " +
              dir / "c.png" + " --width 32 --height 32 --background black");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  int lit = 0;
  for (uint8_t v : read_png(dir / "c.png").rgb) lit += v > 40;
  EXPECT_GT(lit, 3 * 40) << "box outline";
}

// A thin grid (here 4 levels) renders as a map by default: from above, north up, opacity per
// box height, the map's aspect; exactly what those settings give when spelled out.
TEST_F(RenderCli, ThinGridsRenderAsAMapFromAboveByDefault) {
  const std::string common = "render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json";
  auto r = run_cli(common + " --out " + dir / "map.png");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image map = read_png(dir / "map.png");
  EXPECT_EQ(map.width, 512u);
  EXPECT_EQ(map.height, 427u);  // 512 * 5 / 6
  // Box 6 long and 4 high: opacity scale 20 * 6 / 4.
  r = run_cli(common + " --out " + dir / "spelled.png" +
              " --azimuth -90 --elevation 90 --opacity-scale 30 --width 512 --height 427");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(read_png(dir / "spelled.png").rgb, map.rgb);
}

// optimize says the factor too where it renders (the report, an image-based solver), so that a
// scale given with --opacity-scale can be given scaled; a voxel fit without a report renders
// nothing and says nothing of it.
TEST_F(RenderCli, OptimizeSaysTheThinGridsOpacityScaleWhereItRenders) {
  const std::string a = dir / "a_6x5x4_float32.raw";
  const std::string common = "optimize --ref " + a + " --ref-tf " + dir / "tf.json" + " --field " + a;
  const std::string note = "note: a thin grid (6x5x4): seen from above, north up; opacity scale 20 x box length / height";
  auto r = run_cli(common + " --out " + dir / "with_report.json" + " --report " + dir / "report" + " --width 64 --height 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(note), std::string::npos) << r.output;
  r = run_cli(common + " --out " + dir / "image_based.json" + " --solver diffdvr --views-per-iteration 1 --view-pool 0 --iterations 1 --image-size 16");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(note), std::string::npos) << r.output;
  r = run_cli(common + " --out " + dir / "voxels.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("thin grid"), std::string::npos) << r.output;
}

// A grid of one voxel in two axes is a line: at a small size no ray meets its box and the
// picture is the background alone, which the command says (it said nothing, exit 0); a picture
// that shows it does not warn.
TEST_F(RenderCli, APictureNoRayOfWhichMetTheVolumeWarns) {
  std::vector<float> line(64);
  for (size_t i = 0; i < line.size(); ++i) line[i] = float(i);
  write_floats(dir / "line_64x1x1_float32.raw", line);
  const std::string common = "render --volume " + dir / "line_64x1x1_float32.raw" + " --tf " + dir / "tf.json";
  auto r = run_cli(common + " --out " + dir / "small.png" + " --width 64 --height 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("warning: no ray of the 64x64 picture met the volume's box (64x1x1 voxels)"),
            std::string::npos) << r.output;
  r = run_cli(common + " --out " + dir / "large.png" + " --width 512 --height 512");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("no ray"), std::string::npos) << r.output;
  // Rays that meet a box but step across it between two samples: the step is named, not the
  // picture's size.
  write_floats(dir / "cube_16x16x16_float32.raw", std::vector<float>(16 * 16 * 16, 0.5f));
  r = run_cli("render --volume " + dir / "cube_16x16x16_float32.raw" + " --tf " + dir / "tf.json" + " --range 0,1" +
              " --out " + dir / "steps.png" + " --width 64 --height 64 --step 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("the step (--step 64 voxels) is as long as the volume's box is thin (16 voxels)"),
            std::string::npos) << r.output;
}

// A ParaView preset holds sRGB colours; rendered fully opaque over black, its colour must come
// out as the same 8-bit sRGB value ParaView would show (the TF table itself is linear).
TEST_F(RenderCli, PresetColoursRenderAsParaViewShowsThem) {
  struct Case {
    const char* srgb;
    std::array<int, 3> expected;
  };
  // Grey 0.5, and viridis at its midpoint (matplotlib's table: 0.127568, 0.566949, 0.550556).
  for (const Case& c : {Case{"0.5,0.5,0.5", {128, 128, 128}}, Case{"0.127568,0.566949,0.550556", {33, 145, 140}}}) {
    std::ofstream(dir / "preset.json") << "[{\"Name\": \"flat\", \"ColorSpace\": \"RGB\", \"RGBPoints\": [0," << c.srgb
                                       << ", 1," << c.srgb << "], \"Points\": [0, 1, 0.5, 0, 1, 1, 0.5, 0]}]";
    // Opacity 1 at a huge extinction: the first sample is opaque, so no background shows.
    auto r = run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "preset.json" + " --out " +
                     dir / "p.png" + " --width 16 --height 16 --elevation 90 --background black --opacity-scale 100000");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const Image img = read_png(dir / "p.png");
    const uint8_t* centre = img.at(8, 8);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(int(centre[k]), c.expected[k], 1) << c.srgb << " channel " << k;
  }
}

// On a CPU device that reads host memory the field is rendered where it was loaded, not copied:
// a 128 MiB field renders under a budget that has no room for a second copy (it was refused,
// "uploading the field: needs 128 MiB"), within the budget.
TEST_F(RenderCli, ACpuDeviceRendersTheFieldWhereItWasLoaded) {
  const test::CliResult devices = run_cli("devices");
  if (devices.output.find("(CPU)") == std::string::npos) GTEST_SKIP() << "no CPU device first";
  const std::string big = dir / "big_256x256x512_float32.raw";
  {
    std::vector<float> values(256 * 256 * 512);
    for (size_t i = 0; i < values.size(); ++i) values[i] = float(i % 1013) / 1013.0f;
    write_floats(big, values);
  }
  const test::CliResult r = run_cli("--max-memory 280M render --volume " + big + " --tf viridis --out " + dir / "big.png");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_LT(r.peak_rss_bytes, uint64_t(280) << 20) << "peak RSS " << r.peak_rss_bytes;
}

TEST_F(RenderCli, MetricsOfIdenticalImages) {
  ASSERT_EQ(run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json" + " --out " +
                    dir / "a.png" + " --width 24 --height 24").exit_code, 0);
  auto r = run_cli("metrics " + dir / "a.png" + " " + dir / "a.png" + " --json -");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j["rmse"], 0.0);
  EXPECT_EQ(j["psnr"], "inf");
  EXPECT_DOUBLE_EQ(j["ssim"].get<double>(), 1.0);
  // Reading and decoding the two PNGs is the read phase (it counted nowhere, all in other_ms).
  EXPECT_GT(j["timings"]["read_ms"].get<double>(), 0.0) << j["timings"].dump();
  r = run_cli("metrics " + dir / "a.png" + " " + dir / "a.png");
  EXPECT_NE(r.output.find("PSNR inf"), std::string::npos) << r.output;
}

TEST_F(RenderCli, ResidualWritesTheMapAndItsPicture) {
  auto r = run_cli("residual --ref " + dir / "a_6x5x4_float32.raw" + " --ref-tf " + dir / "tf.json" + " --field " +
                   dir / "b_6x5x4_float32.raw" + " --field-tf " + dir / "tf.json" + " --out " + dir / "res.raw" +
                   " --image " + dir / "res.png" + " --width 20 --height 20");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(std::filesystem::file_size(dir / "res.raw"), 6u * 5 * 4 * 4);
  EXPECT_NE(r.output.find("--dims 6,5,4"), std::string::npos) << "tells how to read the raw file back";
  EXPECT_EQ(read_png(dir / "res.png").width, 20u);
}

// A residual's picture maps the data's own range, so it carries its colour bar in a strip beneath
// (--no-color-bar leaves it out); render adds one with --color-bar, the picture above unchanged.
TEST_F(RenderCli, ColorBarsGoBeneathPicturesThatStandAlone) {
  const std::string residual = "residual --ref " + dir / "a_6x5x4_float32.raw" + " --ref-tf " + dir / "tf.json" +
                               " --field " + dir / "b_6x5x4_float32.raw" + " --field-tf " + dir / "tf.json" + " --out " +
                               dir / "res.raw --width 160 --height 64 --image ";
  ASSERT_EQ(run_cli(residual + dir / "bar.png").exit_code, 0);
  ASSERT_EQ(run_cli(residual + dir / "plain.png --no-color-bar").exit_code, 0);
  const Image bar = read_png(dir / "bar.png"), plain = read_png(dir / "plain.png");
  EXPECT_EQ(bar.width, 160u);
  EXPECT_EQ(bar.height, 64u + kColorBarStripHeight);
  EXPECT_EQ(plain.height, 64u);
  EXPECT_TRUE(std::equal(plain.rgb.begin(), plain.rgb.end(), bar.rgb.begin()));
  // The bar's colours are the residual TF's: light yellow at its left end to dark red at its right.
  const TransferFunction res_tf = residual_transfer_function();
  std::vector<Rgb8> strip;
  for (uint32_t x = 0; x < bar.width; ++x) {
    const uint8_t* p = bar.at(x, 64 + 8);
    if (!(p[0] == p[1] && p[1] == p[2])) strip.push_back({p[0], p[1], p[2]});
  }
  ASSERT_GE(strip.size(), 90u);
  const Rgba lo = res_tf.eval(0.5 / double(strip.size())), hi = res_tf.eval(1.0 - 0.5 / double(strip.size()));
  EXPECT_EQ(strip.front(), srgb8(lo[0], lo[1], lo[2]));
  EXPECT_EQ(strip.back(), srgb8(hi[0], hi[1], hi[2]));

  const std::string render = "render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json" +
                             " --height 64 --out ";
  ASSERT_EQ(run_cli(render + dir / "r.png --width 160").exit_code, 0);
  ASSERT_EQ(run_cli(render + dir / "rb.png --width 160 --color-bar").exit_code, 0);
  const Image r = read_png(dir / "r.png"), rb = read_png(dir / "rb.png");
  EXPECT_EQ(r.height, 64u) << "render adds none unless asked";
  EXPECT_EQ(rb.height, 64u + kColorBarStripHeight);
  EXPECT_TRUE(std::equal(r.rgb.begin(), r.rgb.end(), rb.rgb.begin()));
  // Too narrow: said, and the picture written without one.
  const test::CliResult narrow = run_cli(render + dir / "n.png --color-bar --width 100");
  ASSERT_EQ(narrow.exit_code, 0) << narrow.output;
  EXPECT_NE(narrow.output.find("no colour bar: the picture is narrower than 120 pixels"), std::string::npos) << narrow.output;
  EXPECT_EQ(read_png(dir / "n.png").height, 64u);
  // Without --image, the flag shapes nothing: a usage error as the other picture settings.
  const test::CliResult bare = run_cli(residual.substr(0, residual.find(" --width")) + " --no-color-bar");
  EXPECT_EQ(bare.exit_code, 2) << bare.output;
  EXPECT_NE(bare.output.find("--no-color-bar"), std::string::npos) << bare.output;
}

TEST_F(RenderCli, ErrorsNameTheProblem) {
  struct Case {
    std::string args, needle;
  };
  const Case cases[] = {
      {"render --volume " + dir / "missing.raw" + " --tf " + dir / "tf.json" + " --out " + dir / "x.png",
       "missing.raw"},
      {"render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json" + " --out " + dir / "x.png" +
           " --background purple",
       "--background"},
      {"render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json" + " --out " + dir / "x.png" +
           " --elevation 95",
       "--elevation"},
      {"metrics " + dir / "tf.json" + " " + dir / "tf.json", "tf.json"},
  };
  for (const Case& c : cases) {
    auto r = run_cli(c.args);
    EXPECT_NE(r.exit_code, 0) << c.args;
    EXPECT_NE(r.output.find(c.needle), std::string::npos) << c.args << "\n" << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
}

TEST_F(RenderCli, OptimizeAndDemoWriteReports) {
  auto r = run_cli("optimize --ref " + dir / "a_6x5x4_float32.raw" + " --ref-tf " + dir / "tf.json" + " --field " +
                   dir / "b_6x5x4_float32.raw" + " --out " + dir / "opt.json" + " --tf-size 8 --report " +
                   dir / "rep" + " --width 24 --height 24");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir / "rep/index.html"));
  EXPECT_NE(r.output.find("report:"), std::string::npos) << r.output;
  r = run_cli("demo --size 12 --out " + dir / "demo" + " --width 24 --height 24");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto m = nlohmann::json::parse(std::ifstream(dir / "demo/metrics.json"));
  EXPECT_TRUE(m["images"]["optimized_tf"].contains("ssim"));
}

// A TF file's range that misses the field: b spans [6, 10], the TF says [0, 1].
TEST_F(RenderCli, TfRangesThatMissTheFieldWarnOrFail) {
  std::ofstream(dir / "unit.json") << R"({"range": [0, 1], "rgba": [[0,0,1,0.1],[0,1,0,0.6],[1,0,0,0.9]]})";
  const std::string b = dir / "b_6x5x4_float32.raw", a = dir / "a_6x5x4_float32.raw";
  auto r = run_cli("render --volume " + b + " --tf " + dir / "unit.json" + " --out " + dir / "r.png" + " --width 8 --height 8");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("100.0 % of its finite values lie outside the TF file's range [0, 1] (0 below, 120 above"),
            std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--allow-out-of-range"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "r.png"));
  r = run_cli("render --volume " + b + " --tf " + dir / "unit.json" + " --out " + dir / "r.png" +
              " --width 8 --height 8 --allow-out-of-range");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("warning:"), std::string::npos) << r.output;
  // a's values are (i % 13) / 12: 11/12 and 12/12 lie above 0.9, 18 of 120 (15 %): a warning only.
  r = run_cli("render --volume " + a + " --tf " + dir / "tf.json" + " --range 0,0.9 --out " + dir / "r.png" +
              " --width 8 --height 8");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("15.0 % of its finite values lie outside the --range range"), std::string::npos) << r.output;
  // optimize: an error, then with the flag a warning in the summary and the JSON.
  const std::string opt = "optimize --ref " + b + " --ref-tf " + dir / "unit.json" + " --field " + a + " --out " +
                          dir / "o.json" + " --tf-size 8 --json " + dir / "s.json";
  r = run_cli(opt);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("the reference TF file's range"), std::string::npos) << r.output;
  r = run_cli(opt + " --allow-out-of-range");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("warning: " + b), std::string::npos) << r.output;
  const auto j = nlohmann::json::parse(std::ifstream(dir / "s.json"));
  ASSERT_FALSE(j["warnings"].empty());
  EXPECT_NE(j["warnings"][0].get<std::string>().find("0 below, 120 above"), std::string::npos) << j.dump();
}

TEST_F(RenderCli, BenchRenderReportsBothRenderers) {
  auto r = run_cli("bench-render --size 16 --images 16 --repeat 1 --cpu-rows 4 --json " + dir / "b.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(std::ifstream(dir / "b.json"));
  EXPECT_GT(j["results"][0]["gpu_samples_per_s"].get<double>(), 0.0);
  EXPECT_GT(j["results"][0]["cpu_samples_per_s"].get<double>(), 0.0);
}

}  // namespace
}  // namespace tfm
