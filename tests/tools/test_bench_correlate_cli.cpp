// `tfmatch bench-correlate` as a user runs it, on tiny sizes: the table and the JSON name every
// (measure, member count) with rates that are its voxels over its times, and bad options fail
// clearly.
#include <cstdio>
#include <fstream>
#include <regex>
#include <set>
#include <string>

#include <gtest/gtest.h>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/kernels/correlation.h"

namespace tfm {
namespace {

// Each row's rates are its voxels over its measured times, its strategy the kernel's for that
// measure and member count, its GPU and CPU fields agree within the kernels' error bounds, and the
// table prints the JSON's numbers.
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
  EXPECT_EQ(j["bins"], 16);
  EXPECT_EQ(j["k"], 3);
  std::set<std::pair<std::string, int>> seen;
  for (const auto& row : j["results"]) {
    const std::string measure = row["measure"].get<std::string>();
    const uint32_t members = row["members"].get<uint32_t>();
    SCOPED_TRACE(measure + " M=" + std::to_string(members));
    seen.insert({measure, int(members)});
    const double voxels = row["voxels"].get<double>(), gpu_s = row["gpu_s"].get<double>(),
                 cpu_s = row["cpu_s"].get<double>();
    EXPECT_EQ(voxels, 300);
    ASSERT_GT(gpu_s, 0.0);
    ASSERT_GT(cpu_s, 0.0);
    EXPECT_DOUBLE_EQ(row["gpu_voxels_per_s"].get<double>(), voxels / gpu_s);
    EXPECT_DOUBLE_EQ(row["cpu_voxels_per_s"].get<double>(), voxels / cpu_s);
    EXPECT_DOUBLE_EQ(row["ratio"].get<double>(), voxels / gpu_s / (voxels / cpu_s));
    const CorrelationParams params{parse_correlation_measure(measure), 16, 3};
    EXPECT_EQ(row["strategy"], CorrelationKernel::strategy(params, members));
    // Each side within the bound of the exact value (kernels/correlation.h), so within twice it
    // of each other.
    EXPECT_LE(row["max_abs_difference"].get<double>(), 2 * CorrelationKernel::error_bound(params, members));
    // The kernels alone on the ensemble already on the device (the run fails unless their field
    // has compute()'s bits), beside the read bound of the ensemble's bytes: none for the 1500
    // values of M = 5 (halves under 1024 values), measured for the 12 000 of M = 40.
    const double res_ms = row["resident_ms"].get<double>(), bound = row["read_bound_bytes_per_s"].get<double>();
    ASSERT_GT(res_ms, 0.0);
    EXPECT_DOUBLE_EQ(row["resident_voxels_per_s"].get<double>(), voxels / (res_ms * 1e-3));
    if (members == 5) {
      EXPECT_EQ(bound, 0.0);
      EXPECT_EQ(row["resident_over_read_bound"].get<double>(), 0.0);
    } else {
      ASSERT_GT(bound, 0.0);
      EXPECT_DOUBLE_EQ(row["resident_over_read_bound"].get<double>(), members * voxels * 4.0 / (res_ms * 1e-3) / bound);
    }
    // The table's line for this row: its rates as printed (%.4g).
    char rates[64];
    std::snprintf(rates, sizeof rates, "%13.4g %13.4g", row["gpu_voxels_per_s"].get<double>(),
                  row["cpu_voxels_per_s"].get<double>());
    const size_t at = r.output.find(rates);
    ASSERT_NE(at, std::string::npos) << "no line with '" << rates << "' in\n" << r.output;
    const size_t start = r.output.rfind('\n', at) + 1;
    const std::string line = r.output.substr(start, r.output.find('\n', at) - start);
    EXPECT_TRUE(std::regex_search(line, std::regex("^" + measure + " +" + std::to_string(members) + " +300 "))) << line;
  }
  EXPECT_EQ(seen.size(), 6u);
  EXPECT_TRUE(seen.count({"mi-coefficient", 40}));
}

// A few voxels over many members hold those voxels' values, not whole slices of the grid: one
// voxel of 4000 members held 1.4 GB (88 000 voxels a member) before.
TEST(BenchCorrelateCli, FewVoxelsOfManyMembersHoldOnlyThoseVoxels) {
  const test::CliResult r = test::run_cli("-q bench-correlate --voxels 1 --members 4000 --measures pearson --cpu-threads 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("pearson"), std::string::npos) << r.output;
  EXPECT_LT(r.peak_rss_bytes, 600ull << 20) << "peak RSS " << (r.peak_rss_bytes >> 20) << " MiB";
}

TEST(BenchCorrelateCli, RejectsUnknownMeasureAndTooFewMembers) {
  test::CliResult r = test::run_cli("-q bench-correlate --measures pearsn");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--measures"), std::string::npos) << r.output;
  r = test::run_cli("-q bench-correlate --members 2");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--members"), std::string::npos) << r.output;
  // A thread count no machine has is a usage error naming the option (was errno's text).
  r = test::run_cli("-q bench-correlate --cpu-threads 100000000");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--cpu-threads"), std::string::npos) << r.output;
}

// --quick lowers the voxels and the default member counts, never counts the user gave.
TEST(BenchCorrelateCli, QuickKeepsTheMembersGiven) {
  test::TempDir dir;
  const test::CliResult r = test::run_cli("-q bench-correlate --quick --members 7 --measures pearson --json " + (dir / "b.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir / "b.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["results"].size(), 1u) << j.dump();
  EXPECT_EQ(j["results"][0]["members"], 7);
  EXPECT_LE(j["results"][0]["voxels"].get<uint64_t>(), 2000u);
}

}  // namespace
}  // namespace tfm
