// tools/view_latency.py, the plain-HTTP latency client of `tfmatch view` that a lent GPU machine
// runs (tools/gpu-check.sh, part "view"; it has Python, not Node.js): run briefly here so it
// cannot go stale. Its figures are benchmarks (docs/viewer.md), not checked.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <string>

#include "cli_runner.h"
#include "tfmatch/io/json.h"

namespace tfm {
namespace {

TEST(ViewLatencyScript, TimesFourPicturesPerCameraChangeWithTheServersBreakdown) {
  if (std::system("python3 -c 'import http.client, concurrent.futures' >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "no python3";
  test::TempDir dir;
  const std::string json = dir / "latency.json";
  const std::string cmd = std::string("python3 ") + TFMATCH_SOURCE_DIR + "/tools/view_latency.py " + TFMATCH_CLI_PATH +
                          " --size 40 --changes 3 --json " + json + " -- --demo --size 16 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json));
  ASSERT_EQ(j["client_ms"].size(), 3u) << j.dump(1);
  for (const auto& ms : j["client_ms"]) EXPECT_GT(ms.get<double>(), 0.0);
  // The four renders run inside the client's time.
  EXPECT_LT(j["renders_ms_median"].get<double>(), j["client_ms_median"].get<double>());
  for (const char* part : {"wait", "render", "readback", "compose", "decorate", "encode", "kB"})
    ASSERT_TRUE(j["per_picture_median"].contains(part)) << part << " in " << j.dump(1);
  EXPECT_GT(j["per_picture_median"]["kB"].get<double>(), 0.1);
  // Camera changes 2.5 s apart: the server has closed every kept-alive connection (idle for 2 s),
  // and the client connects again, as a browser does, instead of failing.
  const std::string paused = std::string("python3 ") + TFMATCH_SOURCE_DIR + "/tools/view_latency.py " +
                             TFMATCH_CLI_PATH + " --size 40 --changes 1 --pause 2.5 -- --demo --size 16 2>&1";
  EXPECT_EQ(std::system(paused.c_str()), 0) << paused;
  // A program that is not there is a clear error, not a traceback.
  const std::string bad = std::string("python3 ") + TFMATCH_SOURCE_DIR + "/tools/view_latency.py " +
                          (dir / "no-such-program") + " 2>&1";
  EXPECT_NE(std::system(bad.c_str()), 0);
}

}  // namespace
}  // namespace tfm
