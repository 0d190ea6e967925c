// Every case of the kernel case table (host/selftest: sizes, modes, paths, bounds, each kernel
// against its double-precision CPU reference) as one GoogleTest test, quick and large alike, with
// the validation layer on: the same table `tfmatch selftest` runs on a tester's device, so a case
// is written once. A case the device cannot run (a limit or feature it lacks) is skipped, saying
// what it needs. Tests of other properties (determinism across paths, error messages, closed
// forms, finite differences) stay in the other files of this folder.
#include <cctype>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "selftest.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

const std::vector<SelftestCaseEntry>& table() {
  static const std::vector<SelftestCaseEntry> cases = selftest_cases();
  return cases;
}

class KernelCase : public test::GpuTest, public ::testing::WithParamInterface<size_t> {};

TEST_P(KernelCase, MatchesItsCpuReference) {
  const SelftestCase c = run_selftest_case(ctx(), GetParam());
  if (c.status == SelftestStatus::Skipped) GTEST_SKIP() << c.kernel << ", " << c.name << ": " << c.detail;
  EXPECT_EQ(c.status, SelftestStatus::Pass) << c.kernel << " (" << c.wrapper << "), " << c.name << ": " << c.detail;
  EXPECT_GT(c.compared, 0u) << "the case compared nothing";
  EXPECT_LE(c.max_error, c.bound);
}

// "assemble_normal_equations_5003_voxels_N_64_chunks_of_1024_c0": the kernel, the case's words,
// and its index (names must be unique and of letters, digits and underscores).
std::string case_name(const ::testing::TestParamInfo<size_t>& info) {
  const SelftestCaseEntry& e = table()[info.param];
  std::string name = e.kernel + "_";
  for (char ch : e.name) {
    if (std::isalnum(static_cast<unsigned char>(ch)))
      name += ch;
    else if (name.back() != '_')
      name += '_';
  }
  if (name.back() != '_') name += '_';
  return name + "c" + std::to_string(info.param);
}

INSTANTIATE_TEST_SUITE_P(Table, KernelCase, ::testing::Range(size_t(0), table().size()), case_name);

}  // namespace
}  // namespace tfm
