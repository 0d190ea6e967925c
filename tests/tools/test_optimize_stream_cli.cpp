// `tfmatch optimize --stream` as a user runs it: the same TF file as the whole-volume run for raw,
// NetCDF and VTI inputs, the report's note on its box-filtered pictures, and the refusals
// (a solver that does not stream, a truncated file: a message naming the file, nothing written).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "cli_runner.h"
#include "slab_test_files.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::run_cli;

using test::read_text;

class OptimizeStreamCli : public ::testing::Test {
 protected:
  void SetUp() override {
    const Volume ref = slab_test::test_field({37, 29, 23}, 0), field = slab_test::test_field({37, 29, 23}, 6);
    raw_ref = slab_test::write_raw(dir.path(), "ref", ref).string();
    raw_field = slab_test::write_raw(dir.path(), "field", field).string();
    nc_field = slab_test::write_netcdf(dir.path(), "field", field).string() + ":T,time=1";
    vti_ref = slab_test::write_vti_file(dir.path(), "ref", ref, false).string();
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
  }
  std::string args(const std::string& ref, const std::string& field, const std::string& out) const {
    return "optimize --ref " + ref + " --field " + field + " --ref-tf " + (dir / "tf.json").string() + " --out " +
           (dir / out).string() + " --tf-size 24";
  }
  formats_test::TempDir dir;
  std::string raw_ref, raw_field, nc_field, vti_ref;
};

TEST_F(OptimizeStreamCli, SameTfAsTheWholeVolumes) {
  for (const auto& [ref, field] : {std::pair{raw_ref, raw_field}, std::pair{vti_ref, nc_field}}) {
    for (const char* solver : {"normal-equations", "qp"}) {
      SCOPED_TRACE(ref + " / " + field + ", " + solver);
      const std::string s = std::string(" --solver ") + solver + " --smooth 0.001";
      const auto streamed = run_cli(args(ref, field, "streamed.json") + s + " --stream on");
      ASSERT_EQ(streamed.exit_code, 0) << streamed.output;
      EXPECT_NE(streamed.output.find("streamed from disk in 1 slab of 23 z-slices, 2 passes"), std::string::npos) << streamed.output;
      const auto whole = run_cli(args(ref, field, "whole.json") + s + " --stream off");
      ASSERT_EQ(whole.exit_code, 0) << whole.output;
      EXPECT_EQ(read_text(dir / "streamed.json"), read_text(dir / "whole.json"));
    }
  }
}

TEST_F(OptimizeStreamCli, ReportSaysItsPicturesAreBoxFiltered) {
  const auto r = run_cli(args(raw_ref, raw_field, "tf.out.json") + " --stream on --report " + (dir / "rep").string() +
                         " --width 64 --height 64 --json " + (dir / "summary.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(read_text(dir / "rep" / "index.html").find("Streamed run"), std::string::npos);
  EXPECT_NE(read_text(dir / "rep" / "metrics.json").find("\"preview_factor\""), std::string::npos);
  EXPECT_NE(read_text(dir / "summary.json").find("\"passes\": 2"), std::string::npos) << read_text(dir / "summary.json");
}

TEST_F(OptimizeStreamCli, RefusesWhatCannotStream) {
  auto r = run_cli(args(raw_ref, raw_field, "x.json") + " --stream on --solver cgls");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("normal-equations and qp"), std::string::npos) << r.output;
  fs::resize_file(raw_field, fs::file_size(raw_field) - 4);
  r = run_cli(args(raw_ref, raw_field, "x.json") + " --stream on");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find(raw_field), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("bytes"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "x.json"));
}

// The benchmark on tiny sizes: its table, its JSON, and nothing left in its directory.
TEST_F(OptimizeStreamCli, BenchStreamMeasuresAndCleansUp) {
  const fs::path bench = dir / "bench";
  fs::create_directories(bench);
  const auto r = run_cli("bench-stream --voxels 1000,3000 --dir " + bench.string() + " --json " + (dir / "b.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("peak RSS"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("11x11x8"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::is_empty(bench));
  const std::string j = read_text(dir / "b.json");
  EXPECT_NE(j.find("\"peak_rss_bytes\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"read_once_s\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"optimize_over_read\""), std::string::npos) << j;
  EXPECT_NE(r.output.find("optimize / read"), std::string::npos) << r.output;
  EXPECT_NE(j.find("\"streamed\": \"yes\""), std::string::npos) << j;
  // The whole-volume path, for the same ratio.
  const auto whole = run_cli("bench-stream --stream off --voxels 2000 --dir " + bench.string() + " --json " +
                             (dir / "w.json").string());
  ASSERT_EQ(whole.exit_code, 0) << whole.output;
  EXPECT_NE(whole.output.find("--stream off"), std::string::npos) << whole.output;
  EXPECT_TRUE(fs::is_empty(bench));
  const std::string w = read_text(dir / "w.json");
  EXPECT_NE(w.find("\"stream\": \"off\""), std::string::npos) << w;
  EXPECT_EQ(w.find("\"streamed\""), std::string::npos) << w;  // optimize's summary of a whole load
  EXPECT_NE(w.find("\"optimize_over_read\""), std::string::npos) << w;
}

}  // namespace
}  // namespace tfm
