// Test support: one Vulkan context per test process (validation layer on when installed), and a
// check that fails the current test on any validation message.
#pragma once

#include <gtest/gtest.h>

#include "tfmatch/engine/context.h"

namespace tfm::test {

// The process-wide test context (created on first use).
Context& context();

// Fails the current test if validation reported anything since the last call.
void expect_no_validation_messages();

// Fixture for GPU tests: checks validation messages after each test.
class GpuTest : public ::testing::Test {
 protected:
  Context& ctx() { return context(); }
  void TearDown() override { expect_no_validation_messages(); }
};

// Directory of ../shared/data (or of $TFMATCH_SHARED_DATA), or empty when there is none: tests
// then GTEST_SKIP, in the test body itself (a skip inside a helper only leaves the helper).
std::string shared_data_dir();

}  // namespace tfm::test
