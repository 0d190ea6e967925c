// tools/gpu-check.sh, the script a lent GPU machine runs in one device call: its part "startup"
// (the demo, then `optimize` with an empty and a warm pipeline cache) run here on lavapipe, with
// the --deadline and --pack that let a call of fixed length bring its results back as one file.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <sys/wait.h>

#include "cli_runner.h"
#include "tfmatch/io/json.h"

namespace tfm {
namespace {

std::string gpu_check(const std::string& args) {
  const std::string build = std::filesystem::path(TFMATCH_CLI_PATH).parent_path().string();
  return std::string("bash ") + TFMATCH_SOURCE_DIR + "/tools/gpu-check.sh " + args + " " + build;
}

// Unpacks a --pack archive into `into` and lists it.
std::vector<std::string> unpacked(const std::string& archive, const std::filesystem::path& into) {
  std::filesystem::create_directories(into);
  const std::string cmd = "tar -xzf " + archive + " -C " + into.string();
  if (std::system(cmd.c_str()) != 0) return {};
  return test::files_under(into);
}

bool has(const std::vector<std::string>& files, const std::string& name) {
  return std::find(files.begin(), files.end(), name) != files.end();
}

TEST(GpuCheckScript, StartupPartPacksEveryStepsLogsAndJson) {
  test::TempDir dir;
  const std::string out = dir / "out", pack = dir / "gpu.tar.gz";
  const std::string cmd = gpu_check("--parts startup --deadline 300 --pack " + pack) + " " + out + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const std::string summary = test::read_text(dir.path / "out" / "summary.txt");
  for (const char* step : {"startup-demo", "startup-cold", "startup-warm ", "startup-warm-again", "startup-devices"})
    EXPECT_NE(summary.find(std::string(step)), std::string::npos) << step << "\n" << summary;
  size_t steps = 0, passed = 0;
  for (size_t at = summary.find("rc="); at != std::string::npos; at = summary.find("rc=", at + 1)) {
    ++steps;
    passed += summary.compare(at, 5, "rc=0 ") == 0;
  }
  EXPECT_EQ(steps, 5u) << summary;
  EXPECT_EQ(passed, steps) << summary;
  EXPECT_EQ(summary.find("skipped"), std::string::npos) << summary;
  const auto files = unpacked(pack, dir.path / "unpacked");
  EXPECT_TRUE(has(files, "out/summary.txt"));
  EXPECT_TRUE(has(files, "out/startup-devices.log"));
  for (const char* run : {"cold", "warm", "warm-again"}) {
    ASSERT_TRUE(has(files, std::string("out/startup-") + run + ".json")) << run;
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir.path / "unpacked" / "out" / ("startup-" + std::string(run) + ".json")));
    EXPECT_GT(j["timings"]["total_ms"].get<double>(), 0.0) << run;
  }
  // The goals' table (tools/gpu_targets.py) comes back too, every goal of a part not run unmeasured.
  ASSERT_TRUE(has(files, "out/targets.md"));
  const std::string table = test::read_text(dir.path / "unpacked" / "out" / "targets.md");
  EXPECT_NE(table.find("| read bound | "), std::string::npos) << table;
  EXPECT_NE(table.find("step bench did not run"), std::string::npos) << table;
  EXPECT_EQ(test::read_text(dir.path / "out" / "targets.log"), "");
  // The demo's pictures come back, its raw volumes (megabytes that nobody reads there) do not.
  EXPECT_TRUE(has(files, "out/startup-demo/overview.png"));
  EXPECT_TRUE(std::none_of(files.begin(), files.end(), [](const std::string& f) { return f.ends_with(".raw"); }));
  EXPECT_FALSE(std::filesystem::exists(pack + ".part"));
}

TEST(GpuCheckScript, DeadlineSkipsStepsAndBadArgumentsAreRefused) {
  test::TempDir dir;
  const std::string out = dir / "out", pack = dir / "gpu.tar.gz";
  // No time left: every step is skipped with a line saying so, in the order the parts are named,
  // and the pack still comes back.
  const std::string cmd = gpu_check("--parts e2e,startup --deadline 0 --pack " + pack) + " " + out + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const std::string summary = test::read_text(dir.path / "out" / "summary.txt");
  for (const char* step : {"startup-demo", "startup-cold", "e2e"})
    EXPECT_NE(summary.find(std::string(step) + " "), std::string::npos) << step << "\n" << summary;
  EXPECT_EQ(summary.find("rc="), std::string::npos) << summary;
  EXPECT_LT(summary.find("e2e "), summary.find("startup-demo ")) << summary;
  EXPECT_NE(summary.find("skipped: under 5 s left before the --deadline of 0 s"), std::string::npos) << summary;
  EXPECT_TRUE(has(unpacked(pack, dir.path / "unpacked"), "out/summary.txt"));

  // "goals": every part the goals' table reads, the most telling first.
  const std::string goals_cmd = gpu_check("--parts goals --deadline 0") + " " + (dir / "goals") + " 2>&1";
  ASSERT_EQ(std::system(goals_cmd.c_str()), 0) << goals_cmd;
  const std::string goals = "\n" + test::read_text(dir.path / "goals" / "summary.txt");
  size_t at = 0;
  for (const char* step : {"bench ", "e2e ", "torch ", "bench-correlate ", "bench-stream-off ", "view-512 ",
                           "solvers-combustion ", "cuda-tests ", "selftest ", "ctest "}) {
    const size_t found = goals.find(std::string("\n") + step);
    EXPECT_TRUE(found != std::string::npos && found >= at) << step << "\n" << goals;
    at = found == std::string::npos ? at : found;
  }

  // Mistyped arguments end the script at once (exit 2), before any step.
  for (const std::string& bad : std::vector<std::string>{"--parts chek", "--deadline soon", "--pack " + (dir / "bad") + "/p.tar.gz", "--frobnicate"}) {
    // Behind a harmless part and no time, so that a check that lets one through costs nothing.
    const std::string bad_cmd = gpu_check("--parts startup --deadline 0 " + bad) + " " + (dir / "bad") + " >/dev/null 2>&1";
    const int rc = std::system(bad_cmd.c_str());
    EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 2) << bad;
    EXPECT_FALSE(std::filesystem::exists(dir.path / "bad")) << bad;
  }
}

}  // namespace
}  // namespace tfm
