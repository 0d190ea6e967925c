// The solver registry and its typed options (host/solvers/solver.h): every solver listed once,
// every option parses its default and rejects values outside its range, flags of other solvers
// are rejected with the solvers they belong to (library and command line), the typed GPU calls
// give the registry's results, and solver details keep their JSON types.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>

#include "cli_runner.h"
#include "solver_problem.h"
#include "tfmatch/io/json.h"
#include "tfmatch/report/result_json.h"
#include "tfmatch/solvers/solver.h"
#include "tfmatch/solvers/solver_gradient_descent.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}

// Optional components (the CUDA solvers) join before the registry is built, never after: the
// command line's flags come from it once.
TEST(SolverRegistry, ComponentsJoinOnlyBeforeTheRegistryIsBuilt) {
  ASSERT_FALSE(solvers().empty());
  EXPECT_THROW(add_solvers([] { return std::vector<std::unique_ptr<Solver>>{}; }), std::logic_error);
}

TEST(SolverRegistry, ListsEverySolverOnceInNameOrder) {
  std::vector<std::string> expected = {"cgls", "diffdvr", "eigen-cgls", "eigen-normal-equations", "gradient-descent",
                                       "histogram-matching", "irls", "normal-equations", "qp"};
#ifdef TFMATCH_HAVE_CUDA
  expected.insert(expected.begin() + 1, {"cuda-cgls", "cuda-normal-equations"});
#endif
  EXPECT_EQ(solver_names(), expected);
  for (const std::string& name : expected) {
    const Solver* s = find_solver(name);
    ASSERT_NE(s, nullptr) << name;
    EXPECT_EQ(s->name(), name);
    EXPECT_FALSE(s->summary().empty()) << name;
    std::set<std::string> options;
    for (const SolverOption& o : s->options()) {
      EXPECT_TRUE(options.insert(o.name).second) << name << " --" << o.name;
      EXPECT_FALSE(o.help.empty()) << name << " --" << o.name;
    }
  }
  EXPECT_EQ(find_solver("no-such-solver"), nullptr);
  EXPECT_NE(error_of([] { require_solver("no-such-solver"); }).find("unknown solver 'no-such-solver' (available: cgls"),
            std::string::npos);
  EXPECT_EQ(find_solver("diffdvr")->constraints().box, BoxHandling::Projected);
  EXPECT_EQ(find_solver("qp")->constraints().box, BoxHandling::Enforced);
  EXPECT_TRUE(find_solver("diffdvr")->image_based());
}

// Text a user would type for each option's default, and values just outside its range.
std::string default_text(const SolverOption& o) {
  if (const uint64_t* i = std::get_if<uint64_t>(&o.default_value)) return std::to_string(*i);
  if (const double* d = std::get_if<double>(&o.default_value)) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.17g", *d);
    return buf;
  }
  if (const std::string* s = std::get_if<std::string>(&o.default_value)) return *s;
  if (const bool* b = std::get_if<bool>(&o.default_value)) return *b ? "true" : "false";
  return {};
}

std::vector<std::string> bad_values(const SolverOption& o) {
  std::vector<std::string> bad;
  char buf[64];
  switch (o.type) {
    case OptionType::Integer:
      bad = {"2.5", "-1", "x", ""};
      if (o.integer_min > 0) bad.push_back(std::to_string(o.integer_min - 1));
      if (o.integer_max < std::numeric_limits<uint64_t>::max()) bad.push_back(std::to_string(o.integer_max + 1));
      else bad.push_back("18446744073709551616");  // 2^64
      break;
    case OptionType::Number:
      bad = {"nan", "inf", "1x", ""};
      if (std::isfinite(o.range.min)) {
        std::snprintf(buf, sizeof buf, "%.17g",
                      o.range.min_open ? o.range.min : std::nextafter(o.range.min, -INFINITY));
        bad.push_back(buf);
      }
      if (std::isfinite(o.range.max)) {
        std::snprintf(buf, sizeof buf, "%.17g", o.range.max_open ? o.range.max : std::nextafter(o.range.max, INFINITY));
        bad.push_back(buf);
      }
      break;
    case OptionType::Choice: bad = {"no-such-choice", ""}; break;
    case OptionType::Flag: bad = {"maybe"}; break;
    case OptionType::Text: break;
  }
  return bad;
}

TEST(SolverRegistry, EveryOptionParsesItsDefaultAndRejectsValuesOutsideItsRange) {
  for (const auto& solver : solvers()) {
    const std::string name(solver->name());
    // No options given: every option has its default (or, without one, no value).
    const SolverArgs defaults = parse_solver_args(*solver, {});
    for (const SolverOption& o : solver->options()) {
      SCOPED_TRACE(name + " --" + o.name);
      EXPECT_FALSE(defaults.given(o.name));
      if (std::holds_alternative<std::monostate>(o.default_value)) {
        EXPECT_FALSE(defaults.has(o.name));
        EXPECT_FALSE(o.default_help.empty()) << "an option without a default says what the solver picks";
        continue;
      }
      EXPECT_TRUE(defaults.has(o.name));
      EXPECT_EQ(o.parse(default_text(o), name), o.default_value);
      SolverSettings given;
      given.extra[o.name] = default_text(o);
      const SolverArgs parsed = parse_solver_args(*solver, given);
      EXPECT_TRUE(parsed.given(o.name));
      switch (o.type) {
        case OptionType::Integer: EXPECT_EQ(parsed.integer(o.name), defaults.integer(o.name)); break;
        case OptionType::Number: EXPECT_EQ(parsed.number(o.name), defaults.number(o.name)); break;
        case OptionType::Choice:
        case OptionType::Text: EXPECT_EQ(parsed.text(o.name), defaults.text(o.name)); break;
        case OptionType::Flag: EXPECT_EQ(parsed.flag(o.name), defaults.flag(o.name)); break;
      }
      for (const std::string& bad : bad_values(o)) {
        SolverSettings s;
        s.extra[o.name] = bad;
        const std::string e = error_of([&] { parse_solver_args(*solver, s); });
        EXPECT_NE(e.find("--" + o.name + " of solver " + name + ": expected "), std::string::npos) << bad << ": " << e;
        EXPECT_NE(e.find("'" + bad + "'"), std::string::npos) << e;
      }
    }
  }
}

TEST(SolverRegistry, TypedReadsAndRangeEdges) {
  const Solver& gd = require_solver("gradient-descent");
  SolverSettings s;
  s.extra = {{"loss", "l1"}, {"iterations", "1e3"}, {"lr", "0.5"}};
  const SolverArgs a = parse_solver_args(gd, s);
  EXPECT_EQ(a.text("loss"), "l1");
  EXPECT_EQ(a.text("optimizer"), "adam");
  EXPECT_EQ(a.integer("iterations"), 1000u);
  EXPECT_EQ(a.number("lr"), 0.5);
  EXPECT_TRUE(a.given("lr"));
  EXPECT_FALSE(a.given("optimizer"));
  EXPECT_THROW(a.number("iterations"), std::logic_error) << "declared as an integer";
  EXPECT_THROW(a.integer("seed"), std::logic_error) << "not an option of gradient-descent";
  // Open and closed bounds: diffdvr's --lr is in (0, 1].
  const Solver& dd = require_solver("diffdvr");
  s.extra = {{"lr", "1"}, {"seed", "18446744073709551615"}};
  EXPECT_EQ(parse_solver_args(dd, s).number("lr"), 1.0);
  EXPECT_EQ(parse_solver_args(dd, s).integer("seed"), std::numeric_limits<uint64_t>::max());
  s.extra = {{"lr", "0"}};
  EXPECT_THROW(parse_solver_args(dd, s), std::runtime_error);
}

TEST(SolverRegistry, FlagsOfOtherSolversAreRejectedNamingTheirSolvers) {
  SolverSettings s;
  s.extra["lr"] = "0.1";
  EXPECT_EQ(error_of([&] { parse_solver_args(require_solver("normal-equations"), s); }),
            "--lr applies to solvers diffdvr, gradient-descent, not to normal-equations");
  s.extra = {{"init", "reference"}};
  EXPECT_EQ(error_of([&] { parse_solver_args(require_solver("qp"), s); }),
            "--init applies to solver diffdvr, not to qp");
  s.extra = {{"no-such-option", "1"}};
  EXPECT_EQ(error_of([&] { parse_solver_args(require_solver("qp"), s); }), "unknown solver option --no-such-option");
  // A comparison: each option must belong to one of the solvers compared.
  s.extra = {{"iterations", "5"}};
  EXPECT_EQ(error_of([&] { check_options_apply(s, {"qp", "cgls"}); }),
            "--iterations applies to solvers diffdvr, gradient-descent, not to qp, cgls");
  EXPECT_NO_THROW(check_options_apply(s, {"qp", "gradient-descent"}));
}

TEST(SolverRegistry, SharedSolveOptionsAreCheckedAgainstEachSolversConstraints) {
  // --ridge, --smooth and --factorization given (not at their defaults): allowed exactly for the
  // solvers whose constraints() say they honour them, and the error lists those.
  struct Shared {
    const char* flag;
    bool SolverConstraints::*honours;
    void (*give)(SolveOptions&);
  };
  const Shared shared[] = {{"ridge", &SolverConstraints::ridge, [](SolveOptions& o) { o.ridge = 0.1; }},
                           {"smooth", &SolverConstraints::smooth, [](SolveOptions& o) { o.smooth = 0.1; }},
                           {"factorization", &SolverConstraints::factorization,
                            [](SolveOptions& o) { o.factorization = Factorization::LDLT; }}};
  for (const Shared& option : shared) {
    SolverSettings s;
    option.give(s.solve);
    std::string owners;
    for (const auto& solver : solvers())
      if (solver->constraints().*option.honours) owners += (owners.empty() ? "" : ", ") + std::string(solver->name());
    for (const auto& solver : solvers()) {
      SCOPED_TRACE(std::string(option.flag) + " with " + std::string(solver->name()));
      if (solver->constraints().*option.honours) {
        EXPECT_NO_THROW(parse_solver_args(*solver, s));
      } else {
        const std::string e = error_of([&] { parse_solver_args(*solver, s); });
        EXPECT_NE(e.find("--" + std::string(option.flag) + " applies to solver"), std::string::npos) << e;
        EXPECT_NE(e.find(owners + ", not to " + std::string(solver->name())), std::string::npos) << e;
      }
    }
  }
  // Nothing given: every solver runs.
  for (const auto& solver : solvers()) EXPECT_NO_THROW(parse_solver_args(*solver, SolverSettings{}));
  // The ones that do not apply, as users meet them.
  SolverSettings ridge;
  ridge.solve.ridge = 0.5;
  EXPECT_NE(error_of([&] { parse_solver_args(require_solver("diffdvr"), ridge); }).find("not to diffdvr"), std::string::npos);
  SolverSettings ldlt;
  ldlt.solve.factorization = Factorization::LDLT;
  EXPECT_NE(error_of([&] { parse_solver_args(require_solver("cgls"), ldlt); }).find("--factorization applies to solver"),
            std::string::npos);
}

TEST(SolverOptionsCli, InapplicableFlagsAreErrorsAndHelpListsTheSolvers) {
  test::TempDir dir;
  auto r = test::run_cli("optimize --ref " + dir / "ref.raw" + " --ref-tf " + dir / "tf.json" + " --field " +
                         dir / "f.raw" + " --out " + dir / "out.json" + " --lr 0.1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--lr applies to solvers diffdvr, gradient-descent, not to normal-equations"),
            std::string::npos)
      << r.output;
  r = test::run_cli("optimize --ref a --ref-tf b --field c --out " + dir / "out.json" +
                    " --solver cgls --max-iterations 0");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--max-iterations of solver cgls: expected an integer in [1, 1000000000], got '0'"),
            std::string::npos)
      << r.output;
  r = test::run_cli("demo --out " + dir / "demo" + " --solver qp --view-pool 4");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--view-pool applies to solver diffdvr, not to qp"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "demo")) << "the flags are checked before any work";
  r = test::run_cli("solvers --synthetic --size 8x8x4 --solvers normal-equations --tolerance 1e-3");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--tolerance applies to solvers"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not to qp, normal-equations"), std::string::npos) << r.output;

  r = test::run_cli("optimize --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const auto& s : solvers()) {
    EXPECT_NE(r.output.find("  " + std::string(s->name()) + ": " + std::string(s->summary())), std::string::npos)
        << s->name();
    for (const SolverOption& o : s->options()) EXPECT_NE(r.output.find("--" + o.name), std::string::npos) << o.name;
  }
  EXPECT_NE(r.output.find("(solvers: cgls, "), std::string::npos) << "flags name their solvers";
}

class SolverTypedCalls : public test::GpuTest {};

TEST_F(SolverTypedCalls, GradientDescentByTypeEqualsTheRegistrysResult) {
  test::SolverProblem p = test::make_solver_problem(3000, 12, 8, 0.1, 0.9, 51, 0.05);
  p.upload(ctx());
  SolverSettings s;
  s.extra = {{"optimizer", "sgd"}, {"iterations", "15"}};
  s.solve.smooth = 0.01;
  const SolverOutput by_name = p.solve(ctx(), "gradient-descent", s);
  GradientDescentOptions o;
  o.adam = false;
  o.lr = 1.0;  // the registry's default with sgd
  o.iterations = 15;
  o.regularization.smooth = 0.01;
  VoxelProblem problem = p.problem(ctx());
  const GradientDescentResult typed = solve_gradient_descent_gpu(problem, o);
  EXPECT_EQ(typed.tf.rgba, by_name.tf.rgba);
  EXPECT_EQ(typed.last_loss, by_name.details["last_loss"].get<double>());
  o.iterations = 0;
  EXPECT_THROW(solve_gradient_descent_gpu(problem, o), std::invalid_argument);
}

TEST(SolverDetails, KeepOrderKindsAndJsonTypes) {
  Details d;
  d["iterations"] = uint32_t(3);
  d["cond"] = "inf";
  d["residual"] = 0.5;
  d["per_channel"] = std::vector<uint32_t>{1, 2, 3, 4};
  d["curve"] = std::vector<double>{1.0, 0.5};
  d["converged"] = true;
  Details nested;
  nested["views"] = size_t(8);
  nested["loss"] = -1.5;
  d["fixed"] = nested;
  d["iterations"] = int64_t(-2);  // replaces, keeps its place
  std::vector<std::string> names;
  for (const auto& [name, value] : d) names.push_back(name);
  EXPECT_EQ(names, (std::vector<std::string>{"iterations", "cond", "residual", "per_channel", "curve", "converged", "fixed"}));
  EXPECT_EQ(d["iterations"].get<int>(), -2);
  EXPECT_FALSE(d["cond"].is_number());
  EXPECT_EQ(d["fixed"]["views"].get<double>(), 8.0);
  EXPECT_EQ(d["curve"].size(), 2u);
  EXPECT_EQ(d["per_channel"].get<std::vector<double>>(), (std::vector<double>{1, 2, 3, 4}));
  EXPECT_THROW(d["cond"].get<double>(), std::runtime_error);
  const Details& cd = d;
  EXPECT_THROW(cd["absent"], std::out_of_range);
  EXPECT_FALSE(cd.contains("absent"));
  Details copy = d;
  EXPECT_EQ(copy, d);
  copy["fixed"] = 1;
  EXPECT_NE(copy, d);
  // Integers stay integers in JSON (as nlohmann writes them), lists become arrays.
  EXPECT_EQ(to_json(d).dump(),
            R"({"cond":"inf","converged":true,"curve":[1.0,0.5],"fixed":{"loss":-1.5,"views":8},"iterations":-2,)"
            R"("per_channel":[1,2,3,4],"residual":0.5})");
}

}  // namespace
}  // namespace tfm
