// Solvers stop on a cancellation request (host/core/cancellation.h): before any work when it is
// already requested, and within a fraction of a second when it comes from another thread in the
// middle of a long run, with the Cancelled exception passing through to the caller.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "cancellation.h"
#include "normal_equations.h"
#include "solver_problem.h"
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

TEST_F(SolverCancellation, RequestFromAnotherThreadStopsALongRun) {
  test::SolverProblem p = test::make_solver_problem(20000, 32, 9, 0.0, 1.0, 5);
  p.upload(ctx());
  SolverSettings settings;
  settings.extra["iterations"] = "10000000";  // hours of work
  std::thread canceller([] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    request_cancel();
  });
  const double seconds = expect_cancelled([&] { p.solve(ctx(), "gradient-descent", settings); });
  canceller.join();
  // 0.3 s until the request, then at most one batch of iterations (a few ms each on lavapipe);
  // the bound leaves room for a loaded 2-core machine.
  EXPECT_LT(seconds, 5.0);
}

}  // namespace
}  // namespace tfm
