// The rendering commands run as a user runs them: render, residual, metrics, bench-render,
// demo and optimize with --report, and their errors.
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli_runner.h"
#include "png_io.h"

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
  // A transparent TF over a black background is black everywhere.
  r = run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "clear.json" + " --out " +
              dir / "c.png" + " --width 8 --height 8 --background black");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (uint8_t v : read_png(dir / "c.png").rgb) ASSERT_EQ(v, 0);
}

TEST_F(RenderCli, MetricsOfIdenticalImages) {
  ASSERT_EQ(run_cli("render --volume " + dir / "a_6x5x4_float32.raw" + " --tf " + dir / "tf.json" + " --out " +
                    dir / "a.png" + " --width 24 --height 24").exit_code, 0);
  auto r = run_cli("metrics " + dir / "a.png" + " " + dir / "a.png" + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j["rmse"], 0.0);
  EXPECT_EQ(j["psnr"], "inf");
  EXPECT_DOUBLE_EQ(j["ssim"].get<double>(), 1.0);
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

TEST_F(RenderCli, BenchRenderReportsBothRenderers) {
  auto r = run_cli("bench-render --size 16 --images 16 --repeat 1 --cpu-rows 4 --json " + dir / "b.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto j = nlohmann::json::parse(std::ifstream(dir / "b.json"));
  EXPECT_GT(j["results"][0]["gpu_samples_per_s"].get<double>(), 0.0);
  EXPECT_GT(j["results"][0]["cpu_samples_per_s"].get<double>(), 0.0);
}

}  // namespace
}  // namespace tfm
