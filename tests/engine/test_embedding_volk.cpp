// A host that uses volk itself (its own volk.c, under volk's own names) and embeds tfmatch: the
// program links without duplicate symbols, tfmatch runs on the adopted device, and the host's
// volk globals stay exactly as the host set them, also while tfmatch owns a device of its own.
#include "adopted_device_check.h"
#include "host_device.h"
#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/context.h"

// After tfmatch's headers: fine, because this host defines VK_NO_PROTOTYPES, as volk asks.
#include <volk.h>

#include <cstdint>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

namespace tfm {
namespace {

// Some of the host's volk globals: loader-, instance- and device-level, and what volk loaded.
auto host_volk_state() {
  return std::make_tuple(reinterpret_cast<void*>(vkGetInstanceProcAddr), reinterpret_cast<void*>(vkCreateInstance),
                         reinterpret_cast<void*>(vkGetDeviceProcAddr), reinterpret_cast<void*>(vkDestroyInstance),
                         reinterpret_cast<void*>(vkCreateBuffer), reinterpret_cast<void*>(vkQueueSubmit),
                         reinterpret_cast<void*>(vkCmdDispatch), volkGetLoadedInstance(), volkGetLoadedDevice());
}

TEST(EmbeddingVolk, AdoptsTheHostDeviceAndLeavesTheHostsVolkAlone) {
  test::HostDevice host;
  ASSERT_NO_FATAL_FAILURE(host.create());
  const auto before = host_volk_state();
  ASSERT_EQ(volkGetLoadedDevice(), host.device());

  test::expect_adopted_device_computes(host.external());
  {
    // A device tfmatch creates and owns, next to the host's: its instance must not become volk's.
    auto own = Context::create();
    std::vector<uint32_t> words{1, 2, 3, 5, 8, 13, 21}, back(words.size(), 0);
    Buffer b(*own, words.size() * 4, MemoryUsage::Device, "own device");
    upload(*own, b, words.data(), words.size() * 4);
    readback(*own, b, back.data(), back.size() * 4);
    EXPECT_EQ(words, back);
    for (const auto& m : own->take_validation_messages()) ADD_FAILURE() << "validation (tfmatch's device): " << m;
  }
  EXPECT_TRUE(host_volk_state() == before) << "tfmatch changed the host's volk globals";
  EXPECT_EQ(host.wait_idle(), VK_SUCCESS);
  for (const auto& m : host.messages()) ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace tfm
