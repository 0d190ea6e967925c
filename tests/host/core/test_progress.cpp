// Progress in logs: when stderr is not a terminal, a plain line per interval with percent, elapsed
// time and time left; nothing within the first interval; durations written for people.
#include <gtest/gtest.h>

#include <regex>
#include <thread>

#include "progress.h"

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

// Captured stderr is a file, not a terminal: the plain-line mode.
std::string lines_of(double interval_s, uint64_t total, const std::vector<uint64_t>& updates) {
  set_progress_interval(interval_s);
  testing::internal::CaptureStderr();
  {
    Progress p("diffdvr", total);
    for (uint64_t u : updates) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      p.update(u);
    }
  }
  set_progress_interval(0);  // back to the environment's (or the default)
  return testing::internal::GetCapturedStderr();
}

TEST(Progress, PlainLinesWithPercentElapsedAndTimeLeft) {
  const std::string out = lines_of(1e-6, 50, {0, 20, 50});
  // Nothing done yet: the time left is unknown. 20 of 50 after t: 1.5 t left.
  EXPECT_TRUE(std::regex_search(out, std::regex(R"(^diffdvr: 0% \(0/50\), [0-9.]+s elapsed, \? left\n)"))) << out;
  EXPECT_TRUE(std::regex_search(out, std::regex(R"(\ndiffdvr: 40% \(20/50\), [0-9.]+s elapsed, ~[0-9.]+s left\n)"))) << out;
  EXPECT_TRUE(std::regex_search(out, std::regex(R"(\ndiffdvr: 100% \(50/50\), [0-9.]+s elapsed, ~0\.0s left\n$)"))) << out;
  EXPECT_EQ(out.find('\r'), std::string::npos) << "no terminal redraws in a log";
  // Unknown total: the count.
  EXPECT_TRUE(std::regex_search(lines_of(1e-6, 0, {7}), std::regex(R"(^diffdvr: 7 done, [0-9.]+s elapsed\n$)")));
}

TEST(Progress, NothingWithinTheFirstIntervalOrWhenSwitchedOff) {
  EXPECT_EQ(lines_of(3600, 50, {10, 20, 50}), "");
  set_progress_enabled(false);
  EXPECT_EQ(lines_of(1e-6, 50, {10, 20, 50}), "");
  set_progress_enabled(true);
}

}  // namespace
}  // namespace tfm
