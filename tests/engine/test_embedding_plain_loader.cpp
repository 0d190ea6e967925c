// A host that calls the system Vulkan loader directly (-lvulkan, no volk) and embeds tfmatch: its
// own Vulkan calls must still reach the loader, and tfmatch must run on the device it adopts.
#include <vulkan/vulkan.h>  // the loader's prototypes first, as such a host includes them

#include <dlfcn.h>

#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "adopted_device_check.h"
#include "host_device.h"
#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/engine/vk_check.h"

namespace tfm {
namespace {

// The defect this guards against: a tfmatch library that defines a global `vkCreateInstance`
// (volk's function pointer, a variable) which the linker picks instead of the loader's export,
// so the host's first Vulkan call jumps into data and crashes.
TEST(EmbeddingPlainLoader, HostCallsResolveToTheLoader) {
  for (auto [name, address] : {std::pair{"vkCreateInstance", reinterpret_cast<void*>(&vkCreateInstance)},
                               std::pair{"vkGetInstanceProcAddr", reinterpret_cast<void*>(&vkGetInstanceProcAddr)},
                               std::pair{"vkCreateBuffer", reinterpret_cast<void*>(&vkCreateBuffer)}}) {
    Dl_info info{};
    ASSERT_NE(dladdr(address, &info), 0) << name;
    ASSERT_NE(info.dli_fname, nullptr) << name;
    EXPECT_TRUE(std::string(info.dli_fname).find("libvulkan") != std::string::npos)
        << name << " resolves into " << info.dli_fname << ", not the Vulkan loader";
  }
}

TEST(EmbeddingPlainLoader, AdoptsTheHostDeviceAndRunsAKernel) {
  test::HostDevice host;
  ASSERT_NO_FATAL_FAILURE(host.create());
  test::expect_adopted_device_computes(host.external());
  EXPECT_EQ(host.wait_idle(), VK_SUCCESS);  // tfmatch let go of the device without destroying it
  for (const auto& m : host.messages()) ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace tfm
