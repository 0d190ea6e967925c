// The process's phase clock (host/model/phase_timer.h): nested scopes count exclusively, a scope
// that yields to an outer one leaves the time to it, untimed threads count nothing.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "tfmatch/model/phase_timer.h"

namespace tfm {
namespace {

constexpr auto kNap = std::chrono::milliseconds(30);

double seconds_in(Phase phase) { return phase_times().seconds[static_cast<size_t>(phase)]; }

struct Gained {
  double a = 0, b = 0;  // what each of the two phases gained
  double wall = 0;      // the wall time of the work
};
// How much each of two phases gained while `work` ran, and how long it ran.
template <class Work>
Gained gained(Phase a, Phase b, Work work) {
  const double a0 = seconds_in(a), b0 = seconds_in(b), t0 = seconds_since_start();
  work();
  const double wall = seconds_since_start() - t0;
  return {seconds_in(a) - a0, seconds_in(b) - b0, wall};
}

TEST(PhaseTimer, InnerScopesCountExclusively) {
  const auto [upload, compute, wall] = gained(Phase::Upload, Phase::Compute, [] {
    PhaseScope transfer(Phase::Upload);
    std::this_thread::sleep_for(kNap);
    PhaseScope wait(Phase::Compute);
    std::this_thread::sleep_for(kNap);
  });
  EXPECT_GE(upload, 0.025);
  EXPECT_GE(compute, 0.025);
  // The outer clock stopped while the inner scope ran: together they are one wall time, not more.
  EXPECT_LE(upload + compute, wall + 1e-6);
}

TEST(PhaseTimer, AScopeThatYieldsLeavesTheTimeToTheOuterOne) {
  // A wait for the device inside an upload is the upload's time (CommandBatch::wait).
  const auto [upload, compute, wall] = gained(Phase::Upload, Phase::Compute, [] {
    PhaseScope transfer(Phase::Upload);
    PhaseScope wait(Phase::Compute, PhaseScope::Nesting::YieldToOuter);
    std::this_thread::sleep_for(kNap);
  });
  EXPECT_GE(upload, 0.025);
  EXPECT_LE(upload, wall + 1e-6);
  EXPECT_EQ(compute, 0.0);
  // Alone, it counts as its own phase.
  const auto [upload_alone, compute_alone, wall_alone] = gained(Phase::Upload, Phase::Compute, [] {
    PhaseScope wait(Phase::Compute, PhaseScope::Nesting::YieldToOuter);
    std::this_thread::sleep_for(kNap);
  });
  EXPECT_EQ(upload_alone, 0.0);
  EXPECT_GE(compute_alone, 0.025);
  EXPECT_LE(compute_alone, wall_alone + 1e-6);
  // And a scope opened inside it nests as inside any other.
  const auto [read, compute_outer, wall_nested] = gained(Phase::Read, Phase::Compute, [] {
    PhaseScope wait(Phase::Compute, PhaseScope::Nesting::YieldToOuter);
    std::this_thread::sleep_for(kNap);
    PhaseScope inner(Phase::Read);
    std::this_thread::sleep_for(kNap);
  });
  EXPECT_GE(read, 0.025);
  EXPECT_GE(compute_outer, 0.025);
  EXPECT_LE(read + compute_outer, wall_nested + 1e-6);
}

TEST(PhaseTimer, UntimedThreadsCountNothing) {
  const auto [read, compute, wall] = gained(Phase::Read, Phase::Compute, [] {
    std::thread([] {
      const UntimedThread overlapped;
      PhaseScope scope(Phase::Read);
      PhaseScope wait(Phase::Compute, PhaseScope::Nesting::YieldToOuter);
      std::this_thread::sleep_for(kNap);
    }).join();
  });
  EXPECT_EQ(read, 0.0);
  EXPECT_EQ(compute, 0.0);
}

}  // namespace
}  // namespace tfm
