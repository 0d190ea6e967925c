// Progress in logs: when stderr is not a terminal, a plain line per interval with percent, elapsed
// time and time left (checked to the digit on a clock the test steps); nothing within the first
// interval; durations written for people.
#include <gtest/gtest.h>

#include <chrono>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "tfmatch/model/progress.h"

namespace tfm {
namespace {

TEST(Progress, DurationsForPeople) {
  EXPECT_EQ(format_duration(0), "0.0s");
  EXPECT_EQ(format_duration(3.24), "3.2s");
  EXPECT_EQ(format_duration(59.94), "59.9s");
  EXPECT_EQ(format_duration(70), "1m10s");
  EXPECT_EQ(format_duration(105.4), "1m45s");
  EXPECT_EQ(format_duration(3599.4), "59m59s");
  EXPECT_EQ(format_duration(7500), "2h05m");
  EXPECT_EQ(format_duration(-1), "?");
}

// The process-wide switches, restored whatever a test did (the binary runs every test in one
// process too, in any order).
struct ProgressSettingsGuard {
  bool enabled = progress_enabled();
  ~ProgressSettingsGuard() {
    set_progress_interval(0);  // back to the environment's (or the default)
    set_progress_enabled(enabled);
  }
};

// Captured stderr is a file, not a terminal: the plain-line mode. Each update comes `step` after
// the previous one on `clock` (none: the real clock, 2 ms apart).
struct Update {
  uint64_t done;
  std::chrono::milliseconds step{2};
};
std::string lines_of(double interval_s, uint64_t total, const std::vector<Update>& updates, bool stepped_clock = false) {
  ProgressSettingsGuard guard;
  set_progress_interval(interval_s);
  // A clock that moves only when the test says: the lines' times are known exactly.
  auto now = std::chrono::steady_clock::time_point{} + std::chrono::hours(1);
  ProgressClock clock;
  if (stepped_clock) clock = [&now] { return now; };
  testing::internal::CaptureStderr();
  {
    Progress p("diffdvr", total, clock);
    for (const Update& u : updates) {
      if (stepped_clock)
        now += u.step;
      else
        std::this_thread::sleep_for(u.step);
      p.update(u.done);
    }
  }
  return testing::internal::GetCapturedStderr();
}

TEST(Progress, TimeLeftAssumesTheRateSoFar) {
  EXPECT_DOUBLE_EQ(estimated_seconds_left(10.0, 20, 50), 15.0);  // 20 of 50 after T: 1.5 T left
  EXPECT_DOUBLE_EQ(estimated_seconds_left(8.0, 1, 5), 32.0);
  EXPECT_DOUBLE_EQ(estimated_seconds_left(25.0, 50, 50), 0.0);
  EXPECT_LT(estimated_seconds_left(3.0, 0, 50), 0.0) << "nothing done: unknown";
  EXPECT_LT(estimated_seconds_left(3.0, 7, 0), 0.0) << "no total: unknown";
}

TEST(Progress, PlainLinesWithPercentElapsedAndTimeLeft) {
  using std::chrono::milliseconds;
  // Nothing done yet: the time left is unknown. 20 of 50 after 10 s: 15 s left. An update within
  // the interval of the previous line prints nothing.
  const std::string out =
      lines_of(1.0, 50, {{0, milliseconds(2000)}, {20, milliseconds(8000)}, {30, milliseconds(500)}, {50, milliseconds(15000)}},
               true);
  EXPECT_EQ(out,
            "diffdvr: 0% (0/50), 2.0s elapsed, ? left\n"
            "diffdvr: 40% (20/50), 10.0s elapsed, ~15.0s left\n"
            "diffdvr: 100% (50/50), 25.5s elapsed, ~0.0s left\n");
  // Minutes for people: 1 of 4 after 70 s, 3.5 minutes left.
  EXPECT_EQ(lines_of(1.0, 4, {{1, milliseconds(70000)}}, true), "diffdvr: 25% (1/4), 1m10s elapsed, ~3m30s left\n");
  // On the real clock too (the default a Progress reads).
  const std::string real = lines_of(1e-6, 50, {{0}, {20}, {50}});
  EXPECT_TRUE(std::regex_search(real, std::regex(R"(^diffdvr: 0% \(0/50\), [0-9.]+s elapsed, \? left\n)"))) << real;
  EXPECT_TRUE(std::regex_search(real, std::regex(R"(\ndiffdvr: 40% \(20/50\), [0-9.]+s elapsed, ~[0-9.]+s left\n)"))) << real;
  EXPECT_TRUE(std::regex_search(real, std::regex(R"(\ndiffdvr: 100% \(50/50\), [0-9.]+s elapsed, ~0\.0s left\n$)"))) << real;
  EXPECT_EQ(real.find('\r'), std::string::npos) << "no terminal redraws in a log";
  // Unknown total: the count.
  EXPECT_EQ(lines_of(1.0, 0, {{7, milliseconds(3000)}}, true), "diffdvr: 7 done, 3.0s elapsed\n");
}

TEST(Progress, NothingWithinTheFirstIntervalOrWhenSwitchedOff) {
  EXPECT_EQ(lines_of(3600, 50, {{10}, {20}, {50}}), "");
  ProgressSettingsGuard guard;
  set_progress_enabled(false);
  EXPECT_EQ(lines_of(1e-6, 50, {{10}, {20}, {50}}), "");
}

}  // namespace
}  // namespace tfm
