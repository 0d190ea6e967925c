// Library messages name the library's parameters (host/model/parameter_names.h): plain names for an
// embedder, the command line's flags once the program installs its style.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "tfmatch/model/image_loss.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {
namespace {

std::string message_of_bad_loss() {
  try {
    parse_image_loss("l3");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}

// The test program runs with the command line's style (tests/support/parameter_style.cpp); each
// test sets the style it checks and puts the program's back.
struct FlagStyleAfterwards {
  ~FlagStyleAfterwards() {
    set_parameter_style([](std::string_view name) { return "--" + std::string(name); });
  }
};

TEST(ParameterNames, PlainForEmbeddersFlagsForTheCommandLine) {
  FlagStyleAfterwards restore;
  set_parameter_style(nullptr);
  EXPECT_EQ(parameter("max-iterations"), "max-iterations");
  EXPECT_EQ(message_of_bad_loss(), "loss: expected l2 or l1, got 'l3'");
  set_parameter_style([](std::string_view name) { return "--" + std::string(name); });
  EXPECT_EQ(parameter("max-iterations"), "--max-iterations");
  EXPECT_EQ(message_of_bad_loss(), "--loss: expected l2 or l1, got 'l3'");
}

// A solver's warning speaks of the library's parameters too: no flag in it by default.
TEST(ParameterNames, SolverWarningsNameNoFlagInThePlainStyle) {
  FlagStyleAfterwards restore;
  set_parameter_style(nullptr);
  NormalEquations eq(3);
  eq.voxels = 10;
  eq.diag = {4.0, 0.0, 6.0};  // entry 1 touched by no voxel: M is singular
  eq.off = {0.0, 0.0};
  eq.rhs.setConstant(3, 4, 0.5);
  const SolveResult r = solve_normal_equations(eq);
  ASSERT_FALSE(r.warnings.empty());
  for (const std::string& w : r.warnings) {
    EXPECT_EQ(w.find("--"), std::string::npos) << w;
    EXPECT_NE(w.find("smooth"), std::string::npos) << w;
  }
}

}  // namespace
}  // namespace tfm
