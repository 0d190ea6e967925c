// Every solver on one problem (host/solvers/solver_comparison.h): they agree where they should, keep
// the box, survive a rank-deficient M with and without regularization without NaN anywhere; and
// `tfmatch solvers` prints its table and JSON, and rejects bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "cli_runner.h"
#include "solver_problem.h"
#include "tfmatch/io/json.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch/report/result_json.h"
#include "tfmatch/solvers/solver_comparison.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

class SolverComparison : public test::GpuTest {};

const std::vector<std::string> kVoxelSolvers = {"qp", "normal-equations", "eigen-normal-equations", "cgls",
                                                "eigen-cgls", "gradient-descent"};

OptimizeRequest request_for(const test::SolverProblem& p) {
  OptimizeRequest req;
  req.ref = &p.ref_volume;
  req.field = &p.opt_volume;
  req.ref_tf = p.ref_tf;
  req.ref_range = FieldRange{0.0, 1.0};
  req.field_range = FieldRange{10.0, 20.0};
  req.tf_size = p.opt_map.tf_size;
  return req;
}

// The largest |x - x_qp| over entries and channels, from the tables themselves: the comparison's
// own column is what these tests check, so it cannot be what they read.
double max_abs_difference(const TransferFunction& x, const TransferFunction& x_qp) {
  EXPECT_EQ(x.size(), x_qp.size());
  double d = 0.0;
  for (size_t j = 0; j < std::min(x.size(), x_qp.size()); ++j)
    for (size_t c = 0; c < 4; ++c) d = std::max(d, std::abs(double(x.rgba[j][c]) - double(x_qp.rgba[j][c])));
  return d;
}

// Kernels are created before the timed runs (a lookup of one made already takes microseconds):
// no row pays for pipelines (qp, run first, showed the assembly's creation as 140 ms of "assemble").
TEST_F(SolverComparison, NoTimedRunCreatesPipelines) {
  const test::SolverProblem p = test::make_solver_problem(6000, 16, 10, 0.2, 0.8, 12, 0.05, 23);
  std::vector<double> creating;  // the process's pipeline-creation seconds as each row ends
  const double before = phase_times().seconds[size_t(Phase::Pipelines)];
  const ComparisonResult r = compare_solvers(ctx(), request_for(p), {"qp", "normal-equations", "cgls", "irls"},
                                             [&](const ComparisonRow&, size_t, size_t) {
                                               creating.push_back(phase_times().seconds[size_t(Phase::Pipelines)]);
                                             });
  ASSERT_EQ(creating.size(), 4u);
  EXPECT_GT(creating.front(), before) << "the kernels were created in this call";
  for (size_t i = 1; i < creating.size(); ++i)
    EXPECT_LT(creating[i] - creating.front(), 1e-3) << r.rows[i].solver << " created pipelines while timed";
}

TEST_F(SolverComparison, AllSolversAgreeWhenConstraintsAreInactive) {
  const test::SolverProblem p = test::make_solver_problem(6000, 16, 10, 0.2, 0.8, 12, 0.05, 19);
  const ComparisonResult r = compare_solvers(ctx(), request_for(p), kVoxelSolvers);
  ASSERT_EQ(r.rows.size(), kVoxelSolvers.size());
  EXPECT_EQ(r.rows[0].solver, "qp");
  ASSERT_EQ(r.rows[0].tf.size(), p.opt_map.tf_size);
  for (const ComparisonRow& row : r.rows) {
    SCOPED_TRACE(row.solver);
    ASSERT_TRUE(row.error.empty()) << row.error;
    const double diff = max_abs_difference(row.tf, r.rows[0].tf);
    EXPECT_EQ(row.max_diff_to_qp, diff) << "the table's max|x-x_qp| column";
    // Direct solves differ from the QP (GPU fixed-point assembly) by the assembly's rounding,
    // < 1e-6; CGLS stops at relative residual 1e-6 in float (< 1e-4, see test_solver_cgls.cpp);
    // gradient descent (300 Adam steps, final step 2e-4) settles within ~1e-3.
    const double tol = row.solver == "gradient-descent" ? 2e-3 : (row.solver == "cgls" ? 1e-4 : 1e-5);
    EXPECT_LT(diff, tol);
    EXPECT_LT(row.kkt, 10 * tol);
    EXPECT_NEAR(row.rmse, r.rows[0].rmse, 1e-3);
    EXPECT_FALSE(row.phases.empty());
    EXPECT_GT(row.total_ms, 0.0);
  }
  const nlohmann::json j = to_json(r);
  EXPECT_EQ(j["rows"].size(), kVoxelSolvers.size());
  EXPECT_EQ(j["rows"][0]["box"], "enforced");
  EXPECT_TRUE(j["rows"][0].contains("kkt_residual"));
  std::ostringstream table;
  r.print_table(table);
  for (const std::string& s : kVoxelSolvers) EXPECT_NE(table.str().find(s), std::string::npos) << s;
}

TEST_F(SolverComparison, RankDeficientWithAndWithoutSmoothnessHasNoNaN) {
  // The second field's range is given twice as wide as its values: the upper half of the TF is
  // touched by no voxel. Reference colours in [0.2, 0.8] keep the box inactive, so every direct
  // and CGLS result equals the QP's.
  test::SolverProblem p = test::make_solver_problem(4000, 16, 10, 0.2, 0.8, 13);
  for (double smooth : {0.0, 0.05}) {
    SCOPED_TRACE("smooth " + std::to_string(smooth));
    OptimizeRequest req = request_for(p);
    req.field_range = FieldRange{10.0, 30.0};
    req.settings.solve.smooth = smooth;
    req.settings.extra["iterations"] = "50";  // gradient descent: only finiteness matters here
    const ComparisonResult r = compare_solvers(ctx(), req, kVoxelSolvers);
    ASSERT_EQ(r.rows.size(), kVoxelSolvers.size());
    ASSERT_EQ(r.rows[0].tf.size(), p.opt_map.tf_size);
    for (const ComparisonRow& row : r.rows) {
      SCOPED_TRACE(row.solver);
      ASSERT_TRUE(row.error.empty()) << row.error;
      const double diff = max_abs_difference(row.tf, r.rows[0].tf);
      EXPECT_TRUE(std::isfinite(diff));
      EXPECT_EQ(row.max_diff_to_qp, diff) << "the table's max|x-x_qp| column";
      EXPECT_TRUE(std::isfinite(row.rmse));
      EXPECT_TRUE(std::isfinite(row.max_diff_to_qp));
      EXPECT_TRUE(std::isfinite(row.kkt));
      EXPECT_FALSE(to_json(r).dump().find("nan") != std::string::npos);
      // The direct and CGLS solvers agree with the QP on the referenced entries and put 0 (no
      // smoothness) or the smooth continuation into the others.
      if (row.solver != "gradient-descent") EXPECT_LT(diff, 1e-4);
    }
  }
}

TEST_F(SolverComparison, UnknownSolverIsAnError) {
  const test::SolverProblem p = test::make_solver_problem(100, 8, 4, 0.2, 0.8, 14);
  EXPECT_THROW(compare_solvers(ctx(), request_for(p), {"qp", "no-such-solver"}), std::runtime_error);
}

TEST(SolversCli, SyntheticTableAndJson) {
  test::TempDir dir;
  const test::CliResult text =
      test::run_cli("solvers --synthetic --size 20x18x6 --solvers normal-equations,cgls --json " + (dir / "s.json"));
  ASSERT_EQ(text.exit_code, 0) << text.output;
  EXPECT_NE(text.output.find("max|x-x_qp|"), std::string::npos) << text.output;
  EXPECT_NE(text.output.find("cgls"), std::string::npos);
  // stdout holds the JSON alone; the per-solver progress lines stay on stderr.
  const test::CliSplitResult json = test::run_cli_split("solvers --synthetic --size 20x18x6 --solvers qp --json -");
  ASSERT_EQ(json.exit_code, 0) << json.output << json.errors;
  EXPECT_NE(json.errors.find("qp"), std::string::npos) << json.errors;
  const nlohmann::json j = nlohmann::json::parse(json.output);
  EXPECT_EQ(j["voxels"], 20 * 18 * 6);
  ASSERT_EQ(j["rows"].size(), 1u);
  EXPECT_EQ(j["rows"][0]["solver"], "qp");
}

// The default list leaves out what cannot run here (the CUDA solvers on a machine without a CUDA
// device), saying why, instead of running it and listing it failed; named, it still runs and fails.
TEST(SolversCli, DefaultListLeavesOutSolversThatCannotRunHere) {
  const ComparisonPlan plan = plan_comparison({}, {});
  size_t unavailable = 0;
  for (const auto& s : solvers()) {
    if (s->image_based()) continue;
    const std::string name(s->name()), why = s->unavailable();
    SCOPED_TRACE(name);
    const bool planned = std::count(plan.solvers.begin(), plan.solvers.end(), name) == 1;
    const auto skipped = std::find_if(plan.skipped.begin(), plan.skipped.end(), [&](const auto& p) { return p.first == name; });
    EXPECT_EQ(planned, why.empty()) << why;
    EXPECT_EQ(skipped != plan.skipped.end(), !why.empty());
    if (skipped != plan.skipped.end()) {
      EXPECT_EQ(skipped->second, why);
      EXPECT_EQ(why.rfind(name, 0), 0u) << "the reason does not lead with the solver's name: " << why;
      ++unavailable;
      const ComparisonPlan named = plan_comparison({}, {name});
      EXPECT_EQ(std::count(named.solvers.begin(), named.solvers.end(), name), 1) << "a named solver is not run";
      EXPECT_TRUE(named.skipped.empty());
    }
  }
#if defined(TFMATCH_HAVE_CUDA)
  if (!find_solver("cuda-cgls")->unavailable().empty()) EXPECT_GE(unavailable, 2u) << "the CUDA solvers were not left out";
#endif
  test::TempDir dir;
  const test::CliResult r = test::run_cli("solvers --synthetic --size 12x10x4 --json " + (dir / "s.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("failed"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("error:"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("not run: ") != std::string::npos, unavailable > 0) << r.output;
  const nlohmann::json j = nlohmann::json::parse(test::read_text(dir / "s.json"));
  EXPECT_EQ(j["skipped"].size(), unavailable);
  EXPECT_EQ(j["rows"].size(), plan.solvers.size());
  for (const auto& row : j["rows"]) EXPECT_FALSE(row.contains("error")) << row.dump();
}

TEST(SolversCli, BadInputIsAClearError) {
  test::CliResult r = test::run_cli("solvers --synthetic --size 20x18x6 --solvers no-such-solver");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("unknown solver 'no-such-solver'"), std::string::npos) << r.output;
  r = test::run_cli("solvers --synthetic --size 20x18");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("XxYxZ"), std::string::npos) << r.output;
  r = test::run_cli("solvers");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--synthetic"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace tfm
