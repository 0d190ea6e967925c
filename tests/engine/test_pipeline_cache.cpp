// The context's pipeline cache: its identity names the device and driver build, data of another
// device or build is refused with a reason before any driver sees it, and the data of one context
// seeds another that creates pipelines through it.
#include <cstdio>
#include <cstring>
#include <memory>
#include <regex>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/cgls_vectors.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using PipelineCacheTest = test::GpuTest;

// A real kernel, whose pipeline the cache then holds.
std::unique_ptr<CglsVectorsKernel> some_pipeline(Context& ctx) { return std::make_unique<CglsVectorsKernel>(ctx); }

// A second device of its own, as the next process would have, with the test context's validation.
std::unique_ptr<Context> second_context() {
  ContextOptions options;
  options.validation = test::context().validation_enabled();
  return Context::create(options);
}

// The header every implementation writes (VkPipelineCacheHeaderVersionOne) for this device.
std::vector<uint8_t> header_for(const Context& ctx) {
  std::vector<uint8_t> h(16 + VK_UUID_SIZE);
  const uint32_t words[4] = {uint32_t(h.size()), VK_PIPELINE_CACHE_HEADER_VERSION_ONE, ctx.properties().vendorID,
                             ctx.properties().deviceID};
  std::memcpy(h.data(), words, sizeof words);
  std::memcpy(h.data() + 16, ctx.properties().pipelineCacheUUID, VK_UUID_SIZE);
  return h;
}

TEST_F(PipelineCacheTest, IdentityNamesVendorDeviceDriverAndUuid) {
  const std::string id = ctx().pipeline_cache_identity();
  EXPECT_TRUE(std::regex_match(id, std::regex("[0-9a-f]{4,8}-[0-9a-f]{4,8}-[0-9a-f]{8}-[0-9a-f]{32}"))) << id;
  char vendor[16];
  std::snprintf(vendor, sizeof vendor, "%04x-", ctx().properties().vendorID);
  EXPECT_EQ(id.rfind(vendor, 0), 0u) << id;
  EXPECT_NE(ctx().pipeline_cache(), VkPipelineCache(VK_NULL_HANDLE));
}

TEST_F(PipelineCacheTest, ForeignOrBrokenHeadersAreRefusedWithAReason) {
  const std::vector<uint8_t> good = header_for(ctx());
  struct Case {
    const char* name;
    std::vector<uint8_t> data;
    const char* needle;
  };
  auto changed = [&](size_t at, uint8_t delta) {
    std::vector<uint8_t> d = good;
    d[at] = uint8_t(d[at] + delta);
    return d;
  };
  std::vector<uint8_t> too_long_header = good;
  too_long_header[0] = 200;  // a header length past the data
  const Case cases[] = {
      {"empty", {}, "shorter"},
      {"short", std::vector<uint8_t>(good.begin(), good.begin() + 20), "shorter"},
      {"header length past the data", too_long_header, "header length"},
      {"version 2", changed(4, 1), "version"},
      {"another vendor", changed(8, 1), "another device"},
      {"another device", changed(12, 1), "another device"},
      {"another driver build", changed(16 + 5, 1), "pipelineCacheUUID"},
  };
  for (const Case& c : cases) {
    std::string why;
    EXPECT_FALSE(ctx().merge_pipeline_cache_data(c.data, &why)) << c.name;
    EXPECT_NE(why.find(c.needle), std::string::npos) << c.name << ": " << why;
  }
}

TEST_F(PipelineCacheTest, DataOfOneContextSeedsAnother) {
  auto first = some_pipeline(ctx());
  const std::vector<uint8_t> data = ctx().pipeline_cache_data();
  ASSERT_GE(data.size(), 16u + VK_UUID_SIZE);
  // What the driver wrote starts with this device's header, as merge_pipeline_cache_data checks.
  const std::vector<uint8_t> header = header_for(ctx());
  EXPECT_TRUE(std::equal(header.begin() + 4, header.end(), data.begin() + 4));

  std::unique_ptr<Context> other = second_context();
  std::string why;
  EXPECT_TRUE(other->merge_pipeline_cache_data(data, &why)) << why;
  auto second = some_pipeline(*other);
  // Merging the same data again (two runs' worth) is harmless.
  EXPECT_TRUE(other->merge_pipeline_cache_data(data, &why)) << why;
  EXPECT_GE(other->pipeline_cache_data().size(), header.size());
  second.reset();
  for (const std::string& m : other->take_validation_messages()) ADD_FAILURE() << m;
}

}  // namespace
}  // namespace tfm
