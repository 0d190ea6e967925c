// SIGINT and SIGTERM at every phase of a run (issue 15, items 1 and 3): the program exits with
// 130 or 143, promptly, and leaves nothing behind — no temporary file, no staged or partial report
// directory, no output. TFMATCH_PAUSE_AT holds a phase open until the signal arrives, so each
// phase is hit for certain; a long gradient descent is interrupted in its real loop; and a step
// that never reaches a checkpoint is cut short by the watchdog.
#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <fstream>
#include <thread>
#include <tuple>

#include "cli_runner.h"

namespace tfm {
namespace {

using test::CliProcess;
using test::files_under;
using test::TempDir;
using test::write_floats;

class CliInterrupts : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<float> ref(4096), field(4096);
    for (size_t i = 0; i < ref.size(); ++i) {
      ref[i] = float(i % 29) / 28.0f;
      field[i] = 2.0f - ref[i] * ref[i];
    }
    write_floats(dir / "ref_16x16x16_float32.raw", ref);
    write_floats(dir / "field_16x16x16_float32.raw", field);
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
    inputs_ = files_under(dir.path);
  }
  std::string optimize_args() const {
    return "optimize --ref " + dir / "ref_16x16x16_float32.raw" + " --field " + dir / "field_16x16x16_float32.raw" +
           " --ref-tf " + dir / "tf.json" + " --out " + dir / "out.json" + " --json " + dir / "out_summary.json" +
           " --report " + dir / "report" + " --width 32 --height 32";
  }
  // Runs `args` paused at `pause`, sends `sig` once it is there, and checks the exit code, the time
  // to stop and that only the inputs remain.
  void interrupt_at(const std::string& args, const std::string& pause, int sig, double max_seconds) {
    SCOPED_TRACE(pause + " " + std::to_string(sig));
    CliProcess p(args, {{"TFMATCH_PAUSE_AT", pause}});
    ASSERT_TRUE(p.wait_for("paused in phase", std::chrono::seconds(120))) << p.output();
    const auto sent = std::chrono::steady_clock::now();
    p.signal(sig);
    const test::CliResult r = p.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
    EXPECT_EQ(r.exit_code, 128 + sig) << r.output;
    EXPECT_LT(seconds, max_seconds) << r.output;
    EXPECT_NE(r.output.find(sig == SIGINT ? "interrupted (SIGINT)" : "interrupted (SIGTERM)"), std::string::npos) << r.output;
    EXPECT_EQ(files_under(dir.path), inputs_) << r.output;
  }
  TempDir dir;
  std::vector<std::string> inputs_;
};

// Every phase of `optimize --out --json --report`: loading, solving, writing the TF (a temporary
// file exists), and the report half done (a staged directory holding some of its pictures); one
// test per phase and signal, so that ctest runs them side by side.
class CliInterruptPhases : public CliInterrupts, public ::testing::WithParamInterface<std::tuple<std::string, int>> {};

TEST_P(CliInterruptPhases, OptimizeStopsCleanly) {
  interrupt_at(optimize_args(), std::get<0>(GetParam()), std::get<1>(GetParam()), 3.0);
}

INSTANTIATE_TEST_SUITE_P(Phases, CliInterruptPhases,
                         ::testing::Combine(::testing::Values("load", "solve", "write", "report#5"),
                                            ::testing::Values(SIGINT, SIGTERM)),
                         [](const auto& info) {
                           std::string phase = std::get<0>(info.param);
                           std::replace(phase.begin(), phase.end(), '#', '_');
                           return phase + (std::get<1>(info.param) == SIGINT ? "_SIGINT" : "_SIGTERM");
                         });

TEST_F(CliInterrupts, RenderAndResidualStopCleanly) {
  const std::string ref = dir / "ref_16x16x16_float32.raw", tf = dir / "tf.json";
  interrupt_at("render --volume " + ref + " --tf " + tf + " --out " + dir / "r.png" + " --width 64 --height 64", "render",
               SIGINT, 3.0);
  interrupt_at("residual --ref " + ref + " --field " + dir / "field_16x16x16_float32.raw" + " --ref-tf " + tf +
                   " --field-tf " + tf + " --out " + dir / "res.vti" + " --image " + dir / "res.png",
               "write", SIGTERM, 3.0);
}

// No pause: a gradient descent of hours stops within a second of the signal, in its own loop.
TEST_F(CliInterrupts, LongSolveStopsWithinASecond) {
  CliProcess p(optimize_args() + " --solver gradient-descent --iterations 100000000", {{"TFMATCH_TRACE_PHASES", "1"}});
  ASSERT_TRUE(p.wait_for("tfmatch: phase solve", std::chrono::seconds(120))) << p.output();
  // Well inside the iterations: the setup before them compiles the assembly and gradient
  // pipelines, about a second each on lavapipe with a cold shader cache, which no checkpoint
  // can interrupt.
  std::this_thread::sleep_for(std::chrono::milliseconds(4000));
  const auto sent = std::chrono::steady_clock::now();
  p.signal(SIGINT);
  const test::CliResult r = p.finish();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
  EXPECT_EQ(r.exit_code, 130) << r.output;
  EXPECT_LT(seconds, 2.0) << r.output;
  EXPECT_EQ(r.output.find("stopped without waiting"), std::string::npos) << "the watchdog had to act:\n" << r.output;
  EXPECT_EQ(files_under(dir.path), inputs_);
}

// A step that never checks (TFMATCH_PAUSE_AT=NAME! ignores the flag, as a long GPU submission
// would): the watchdog removes the temporary file and exits after its grace period.
TEST_F(CliInterrupts, WatchdogStopsAStepWithoutCheckpoints) {
  CliProcess p(optimize_args(), {{"TFMATCH_PAUSE_AT", "write!"}});
  ASSERT_TRUE(p.wait_for("paused in phase write", std::chrono::seconds(120))) << p.output();
  const auto sent = std::chrono::steady_clock::now();
  p.signal(SIGTERM);
  const test::CliResult r = p.finish();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
  EXPECT_EQ(r.exit_code, 143) << r.output;
  EXPECT_NE(r.output.find("stopped without waiting for the current step"), std::string::npos) << r.output;
  EXPECT_LT(seconds, 2.0) << r.output;
  EXPECT_EQ(files_under(dir.path), inputs_);
}

}  // namespace
}  // namespace tfm
