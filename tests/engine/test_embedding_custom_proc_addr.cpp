// A host that hands tfmatch its own vkGetInstanceProcAddr (here a wrapper that records what is
// asked, then forwards to the loader): everything tfmatch calls on the adopted handles must be
// resolved through it, instance- and device-level alike.
#include "adopted_device_check.h"
#include "context.h"
#include "host_device.h"

#include <vulkan/vulkan.h>  // after tfmatch's headers: the loader's prototypes are still declared

#include <cstring>
#include <mutex>
#include <set>
#include <string>

#include <gtest/gtest.h>

namespace tfm {
namespace {

std::mutex requested_mutex;
std::set<std::string> requested;  // names asked of the host's resolvers
PFN_vkGetDeviceProcAddr loader_get_device_proc_addr = nullptr;

void record(const char* name) {
  std::lock_guard lock(requested_mutex);
  requested.insert(name);
}

VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL host_get_device_proc_addr(VkDevice device, const char* name) {
  record(name);
  return loader_get_device_proc_addr(device, name);
}

VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL host_get_instance_proc_addr(VkInstance instance, const char* name) {
  record(name);
  // Device-level commands resolve through the host too when tfmatch asks for vkGetDeviceProcAddr here.
  if (std::strcmp(name, "vkGetDeviceProcAddr") == 0) {
    loader_get_device_proc_addr =
        reinterpret_cast<PFN_vkGetDeviceProcAddr>(vkGetInstanceProcAddr(instance, "vkGetDeviceProcAddr"));
    return reinterpret_cast<PFN_vkVoidFunction>(&host_get_device_proc_addr);
  }
  return vkGetInstanceProcAddr(instance, name);
}

TEST(EmbeddingCustomProcAddr, AdoptResolvesEverythingThroughTheHost) {
  test::HostDevice host;
  ASSERT_NO_FATAL_FAILURE(host.create());
  requested.clear();
  test::expect_adopted_device_computes(host.external(&host_get_instance_proc_addr));
  for (const char* name : {"vkGetDeviceProcAddr", "vkGetPhysicalDeviceProperties",
                           "vkGetPhysicalDeviceQueueFamilyProperties", "vkCreateBuffer", "vkQueueSubmit",
                           "vkCmdDispatch"})
    EXPECT_EQ(requested.count(name), 1u) << name << " was not resolved through the host's function";
  EXPECT_EQ(host.wait_idle(), VK_SUCCESS);
  for (const auto& m : host.messages()) ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace tfm
