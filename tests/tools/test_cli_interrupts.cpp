// SIGINT and SIGTERM at every phase of a run (issue 15, items 1 and 3): the program exits with
// 130 or 143, promptly, and leaves nothing behind — no temporary file, no staged or partial report
// directory, no output. TFMATCH_PAUSE_AT holds a phase open until the signal arrives, so each
// phase is hit for certain; a long gradient descent is interrupted in its real loop; and a step
// that never reaches a checkpoint is cut short by the watchdog.
#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <fstream>
#include <chrono>
#include <tuple>

#include "cli_runner.h"
#include "interrupts.h"

namespace tfm {
namespace {

using namespace std::chrono_literals;
using test::CliProcess;
using test::files_under;
using test::TempDir;
using test::write_floats;

// The program's own promise (tools/cli/interrupts.h): work reaches a checkpoint within
// cli::kGrace of the signal, or the watchdog abandons it and says so; work that stopped there has
// cli::kTeardownGrace more to unwind. The bounds below are those graces plus kExitSlack: the exit
// itself and its output and status reaching this process, milliseconds, scheduled late on a
// loaded two-core machine.
constexpr std::chrono::duration<double> kExitSlack = 1s;
constexpr std::chrono::duration<double> kStopBound = cli::kGrace;
constexpr std::chrono::duration<double> kExitBound = cli::kGrace + cli::kTeardownGrace + kExitSlack;
// What the program prints when checkpoints see the request (TFMATCH_TRACE_PHASES=1) and when the
// watchdog has to act (host/model/cancellation.cpp, tools/cli/interrupts.cpp).
constexpr const char* kStoppingLine = "tfmatch: stopping at a checkpoint";
constexpr const char* kWatchdogLine = "stopped without waiting";

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

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
  // Runs `args` paused at `pause`, sends `sig` once it is there, and checks the exit code, that
  // the work stopped at its checkpoint within the program's graces (the watchdog never acting) and
  // that only the inputs remain.
  void interrupt_at(const std::string& args, const std::string& pause, int sig) {
    SCOPED_TRACE(pause + " " + std::to_string(sig));
    CliProcess p(args, {{"TFMATCH_PAUSE_AT", pause}, {"TFMATCH_TRACE_PHASES", "1"}});
    ASSERT_TRUE(p.wait_for("paused in phase", 120s)) << p.output();
    const auto sent = std::chrono::steady_clock::now();
    p.signal(sig);
    EXPECT_TRUE(p.wait_for(kStoppingLine, std::chrono::duration_cast<std::chrono::milliseconds>(kExitBound)))
        << p.output();
    const double stopped = seconds_since(sent);
    const test::CliResult r = p.finish();
    const double seconds = seconds_since(sent);
    EXPECT_EQ(r.exit_code, 128 + sig) << r.output;
    EXPECT_LT(stopped, kStopBound.count()) << r.output;
    EXPECT_LT(seconds, kExitBound.count()) << r.output;
    EXPECT_EQ(r.output.find(kWatchdogLine), std::string::npos) << "the watchdog had to act:\n" << r.output;
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
  interrupt_at(optimize_args(), std::get<0>(GetParam()), std::get<1>(GetParam()));
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
               SIGINT);
  interrupt_at("residual --ref " + ref + " --field " + dir / "field_16x16x16_float32.raw" + " --ref-tf " + tf +
                   " --field-tf " + tf + " --out " + dir / "res.vti" + " --image " + dir / "res.png",
               "write", SIGTERM);
}

// No pause: a gradient descent of hours stops at a checkpoint of its own loop within the grace,
// unwinds within the teardown grace, and the watchdog never acts.
TEST_F(CliInterrupts, LongSolveStopsWithinASecond) {
  // Progress lines every 50 ms: the first "(N/100000000)" says N iterations are done, so the
  // setup before them (pipeline compilation, which no checkpoint interrupts) is over, however
  // long it took on this machine.
  CliProcess p(optimize_args() + " --solver gradient-descent --iterations 100000000",
               {{"TFMATCH_TRACE_PHASES", "1"}, {"TFMATCH_PROGRESS_INTERVAL", "0.05"}});
  ASSERT_TRUE(p.wait_for("/100000000), ", 120s)) << p.output();
  const auto sent = std::chrono::steady_clock::now();
  p.signal(SIGINT);
  EXPECT_TRUE(p.wait_for(kStoppingLine, std::chrono::duration_cast<std::chrono::milliseconds>(kExitBound)))
      << p.output();
  const double stopped = seconds_since(sent);
  const test::CliResult r = p.finish();
  const double seconds = seconds_since(sent);
  EXPECT_EQ(r.exit_code, 130) << r.output;
  EXPECT_NE(r.output.find("tfmatch: stopping at a checkpoint of phase solve"), std::string::npos) << r.output;
  EXPECT_LT(stopped, kStopBound.count()) << r.output;
  EXPECT_LT(seconds, kExitBound.count()) << r.output;
  EXPECT_EQ(r.output.find(kWatchdogLine), std::string::npos) << "the watchdog had to act:\n" << r.output;
  EXPECT_EQ(files_under(dir.path), inputs_);
}

// A step that never checks (TFMATCH_PAUSE_AT=NAME! ignores the flag, as a long GPU submission
// would): the watchdog waits its grace, then removes the temporary file and exits.
TEST_F(CliInterrupts, WatchdogStopsAStepWithoutCheckpoints) {
  CliProcess p(optimize_args(), {{"TFMATCH_PAUSE_AT", "write!"}});
  ASSERT_TRUE(p.wait_for("paused in phase write", 120s)) << p.output();
  const auto sent = std::chrono::steady_clock::now();
  p.signal(SIGTERM);
  const test::CliResult r = p.finish();
  const double seconds = seconds_since(sent);
  EXPECT_EQ(r.exit_code, 143) << r.output;
  EXPECT_NE(r.output.find("stopped without waiting for the current step"), std::string::npos) << r.output;
  // Not before the grace (the step might have ended by itself), and no teardown grace: the work
  // never stopped at a checkpoint.
  EXPECT_GE(seconds, std::chrono::duration<double>(cli::kGrace).count()) << r.output;
  EXPECT_LT(seconds, std::chrono::duration<double>(cli::kGrace + kExitSlack).count()) << r.output;
  EXPECT_EQ(files_under(dir.path), inputs_);
}

}  // namespace
}  // namespace tfm
