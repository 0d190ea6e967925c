// tools/e2e_timing.py, the end-to-end timing of `optimize` and `correlate` that a lent GPU machine
// runs (tools/gpu-check.sh, part "e2e"): run here on small inputs so it cannot go stale. Its
// figures are benchmarks (README, docs/benchmarks.md), not checked.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "cli_runner.h"
#include "tfmatch/io/json.h"

namespace tfm {
namespace {

TEST(E2eTimingScript, TimesOptimizeAndCorrelateBesideTheDriverFloor) {
  if (std::system("python3 -c 'import argparse, statistics' >/dev/null 2>&1") != 0) GTEST_SKIP() << "no python3";
  test::TempDir dir;
  const std::string json = dir / "e2e.json";
  const std::string cmd = std::string("python3 ") + TFMATCH_SOURCE_DIR + "/tools/e2e_timing.py " + TFMATCH_CLI_PATH +
                          " --pair 24x20x9 --ensemble 4x13x11x3 --runs 2 --dir " + dir.path.string() +
                          " --json " + json + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json));
  for (const char* command : {"optimize", "correlate"}) {
    const auto& r = j[command];
    ASSERT_EQ(r["samples_ms"].size(), 2u) << j.dump(1);
    EXPECT_GT(r["median_ms"].get<double>(), 0.0);
    // The command's own --json timings, from inside the process that the wall time wraps.
    EXPECT_GT(r["timings"]["total_ms"].get<double>(), 0.0) << command;
    EXPECT_LT(r["timings"]["total_ms"].get<double>(), r["samples_ms"][1].get<double>()) << command;
  }
  // optimize's --json phases, its assembly kernel's GPU time among them (tools/gpu_targets.py
  // compares it with bench's).
  bool assembly = false;
  for (const auto& phase : j["optimize"]["phases"]) assembly = assembly || (phase["name"] == "assemble" && phase.contains("gpu_ms"));
  EXPECT_TRUE(assembly) << j["optimize"].dump(1);
  EXPECT_GT(j["driver_floor"]["total_ms"].get<double>(), 0.0);
  EXPECT_FALSE(j["default_sizes"].get<bool>());
  // The inputs went into a directory of their own under --dir, removed afterwards.
  size_t left = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path)) left += e.path().filename() != "e2e.json";
  EXPECT_EQ(left, 0u);
  // A program or directory that is not there is a clear error, not a traceback.
  const std::string no_dir = std::string("python3 ") + TFMATCH_SOURCE_DIR + "/tools/e2e_timing.py " +
                             TFMATCH_CLI_PATH + " --dir " + (dir / "no-such-dir") + " 2>&1";
  EXPECT_NE(std::system(no_dir.c_str()), 0);
  const std::string bad = std::string("python3 ") + TFMATCH_SOURCE_DIR + "/tools/e2e_timing.py " +
                          (dir / "no-such-program") + " 2>&1";
  EXPECT_NE(std::system(bad.c_str()), 0);
}

}  // namespace
}  // namespace tfm
