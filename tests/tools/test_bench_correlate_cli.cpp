// `tfmatch bench-correlate` as a user runs it, on tiny sizes: the table and the JSON name every
// (measure, member count) with positive GPU and CPU rates, and bad options fail clearly.
#include <fstream>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli_runner.h"

namespace tfm {
namespace {

TEST(BenchCorrelateCli, TinyRunWritesTableAndJson) {
  test::TempDir dir;
  const std::string json = dir / "bench.json";
  const test::CliResult r =
      test::run_cli("-q bench-correlate --voxels 300 --members 5,40 --measures kendall,mi-binned,mi-coefficient --json " + json);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("GPU voxels/s"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("one workgroup per voxel"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("one invocation per voxel"), std::string::npos) << r.output;
  std::ifstream in(json);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  ASSERT_TRUE(j.is_object()) << "no JSON in " << json;
  std::set<std::pair<std::string, int>> seen;
  for (const auto& row : j["results"]) {
    seen.insert({row["measure"].get<std::string>(), row["members"].get<int>()});
    EXPECT_EQ(row["voxels"].get<int>(), 300);
    EXPECT_GT(row["gpu_voxels_per_s"].get<double>(), 0.0);
    EXPECT_GT(row["cpu_voxels_per_s"].get<double>(), 0.0);
    EXPECT_NEAR(row["ratio"].get<double>(),
                row["gpu_voxels_per_s"].get<double>() / row["cpu_voxels_per_s"].get<double>(), 1e-9);
  }
  EXPECT_EQ(seen.size(), 6u);
  EXPECT_TRUE(seen.count({"mi-coefficient", 40}));
}

TEST(BenchCorrelateCli, RejectsUnknownMeasureAndTooFewMembers) {
  test::CliResult r = test::run_cli("-q bench-correlate --measures pearsn");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--measures"), std::string::npos) << r.output;
  r = test::run_cli("-q bench-correlate --members 2");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--members"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace tfm
