// Every case of the kernel case table (host/selftest: sizes, modes, paths, bounds, each kernel
// against its double-precision CPU reference), quick and large alike, with the validation layer
// on: the same table `tfmatch selftest` runs on a tester's device, so a case is written once. One
// test per kernel (a process per case would cost more than most cases), each failing case
// reported by name; a case the device cannot run (a limit or feature it lacks) is listed as
// skipped with what it needs. Tests of other properties (determinism across paths, error
// messages, closed forms, finite differences) stay in the other files of this folder.
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tfmatch/selftest/selftest.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

class KernelCases : public test::GpuTest, public ::testing::WithParamInterface<std::string> {};

TEST_P(KernelCases, MatchTheirCpuReferences) {
  const std::vector<SelftestCaseEntry> table = selftest_cases();
  size_t ran = 0, skipped = 0;
  for (size_t i = 0; i < table.size(); ++i) {
    if (table[i].kernel != GetParam()) continue;
    const SelftestCase c = run_selftest_case(ctx(), i);
    if (c.status == SelftestStatus::Skipped) {
      ++skipped;
      std::printf("skipped: %s, %s: %s\n", c.kernel.c_str(), c.name.c_str(), c.detail.c_str());
      continue;
    }
    ++ran;
    EXPECT_EQ(c.status, SelftestStatus::Pass) << "case " << i << ", " << c.name << ": " << c.detail;
    EXPECT_GT(c.compared, 0u) << "case " << i << ", " << c.name << " compared nothing";
    EXPECT_LE(c.max_error, c.bound) << "case " << i << ", " << c.name;
  }
  EXPECT_GT(ran, 0u) << "no case of " << GetParam() << " ran (" << skipped << " skipped)";
  std::printf("%s: %zu cases ran, %zu skipped\n", GetParam().c_str(), ran, skipped);
}

INSTANTIATE_TEST_SUITE_P(Table, KernelCases, ::testing::ValuesIn(selftest_kernels()),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

}  // namespace
}  // namespace tfm
