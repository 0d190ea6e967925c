// Solvers stop on a cancellation request (host/model/cancellation.h): before any work when it is
// already requested, and within the command line's grace (tools/cli/interrupts.h) when it comes
// from another thread in the middle of a long run, with the Cancelled exception passing through
// to the caller.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "interrupts.h"
#include "solver_problem.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/solvers/normal_equations.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

class SolverCancellation : public test::GpuTest {
 protected:
  void TearDown() override {
    reset_cancel();
    test::GpuTest::TearDown();
  }
};

// Runs `solve`, expecting Cancelled; returns the seconds it took.
template <class Solve>
double expect_cancelled(Solve solve) {
  const auto t0 = std::chrono::steady_clock::now();
  bool cancelled = false;
  try {
    solve();
  } catch (const Cancelled&) {
    cancelled = true;
  }
  EXPECT_TRUE(cancelled) << "the solve ran to its end";
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST_F(SolverCancellation, RequestedBeforeTheSolveStopsIt) {
  test::SolverProblem p = test::make_solver_problem(5000, 16, 9, 0.0, 1.0, 3);
  p.upload(ctx());
  request_cancel();
  for (const char* solver : {"qp", "cgls", "gradient-descent"}) {
    SCOPED_TRACE(solver);
    expect_cancelled([&] { p.solve(ctx(), solver); });
  }
  // The O(N) host solve of the largest TF the command line accepts checks as it goes.
  NormalEquations eq(65536);
  for (uint32_t j = 0; j < eq.n; ++j) eq.diag[j] = 1.0;
  eq.rhs.setConstant(0.5);
  eq.voxels = 1;
  expect_cancelled([&] { solve_normal_equations(eq); });
}

// The request comes once the iterations are under way (the solver's progress says so: pipeline
// creation before them has no checkpoint), and the solve stops within the grace the command line
// gives work to reach a checkpoint before its watchdog abandons it (tools/cli/interrupts.h).
TEST_F(SolverCancellation, RequestFromAnotherThreadStopsALongRun) {
  test::SolverProblem p = test::make_solver_problem(20000, 32, 9, 0.0, 1.0, 5);
  p.upload(ctx());
  SolverSettings settings;
  settings.extra["iterations"] = "10000000";  // hours of work
  std::mutex mutex;
  std::condition_variable iterating;
  uint64_t done_seen = 0;
  // On this thread, which runs the solve: its progress reaches the observer.
  ScopedProgressObserver observer([&](const std::string&, uint64_t done, uint64_t) {
    std::lock_guard lock(mutex);
    done_seen = done;
    if (done > 0) iterating.notify_one();
  });
  std::chrono::steady_clock::time_point requested;
  std::thread canceller([&] {
    std::unique_lock lock(mutex);
    // Only against a hang: the first batch of iterations ends within seconds on any machine.
    if (!iterating.wait_for(lock, std::chrono::seconds(120), [&] { return done_seen > 0; }))
      ADD_FAILURE() << "no iteration reported within 120 s";
    requested = std::chrono::steady_clock::now();
    request_cancel();
  });
  expect_cancelled([&] { p.solve(ctx(), "gradient-descent", settings); });
  const auto stopped = std::chrono::steady_clock::now();
  canceller.join();
  EXPECT_GT(done_seen, 0u);
  EXPECT_LT(done_seen, 10000000u) << "the run ended by itself";
  EXPECT_LT(std::chrono::duration<double>(stopped - requested).count(),
            std::chrono::duration<double>(cli::kGrace).count());
}

}  // namespace
}  // namespace tfm
