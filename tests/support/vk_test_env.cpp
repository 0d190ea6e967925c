// Test context creation and validation-message checking.
#include "vk_test_env.h"

#include <cstdlib>
#include <filesystem>
#include <memory>

namespace tfm::test {

Context& context() {
  static std::unique_ptr<Context> ctx = [] {
    ContextOptions options;  // TFMATCH_VALIDATION=1: support/test_process_environment.cpp
    auto c = Context::create(options);
    return c;
  }();
  return *ctx;
}

void expect_no_validation_messages() {
  for (const std::string& m : context().take_validation_messages()) ADD_FAILURE() << "Vulkan validation: " << m;
}

std::string shared_data_dir() {
  // TFMATCH_SHARED_DATA overrides the configured place (a test checks the skips with it).
  const char* env = std::getenv("TFMATCH_SHARED_DATA");
  std::filesystem::path p = env ? env : TFMATCH_SHARED_DATA_DIR;
  return std::filesystem::is_directory(p) ? p.string() : std::string();
}

}  // namespace tfm::test
