// A host application's own Vulkan instance, device and compute queue, created the way the
// embedding tests' hosts create them: through the loader's exported functions, or, compiled with
// TFM_TEST_HOST_USES_VOLK, through the host's own volk. Needs Vulkan's types only.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <vulkan/vulkan_core.h>

#include "tfmatch/engine/context.h"

namespace tfm::test {

class HostDevice {
 public:
  HostDevice() = default;
  ~HostDevice();  // destroys what create() made: the host owns it, not tfmatch
  HostDevice(const HostDevice&) = delete;
  HostDevice& operator=(const HostDevice&) = delete;

  // Instance (with the validation layer and synchronization validation when installed; required
  // when TFMATCH_VALIDATION=1), debug messenger, first physical device, its first compute queue
  // family, device and queue. Stops at the first failed gtest assertion: wrap the call in
  // ASSERT_NO_FATAL_FAILURE.
  void create();
  // The handles for Context::adopt, with `get_instance_proc_addr` passed through.
  ExternalDevice external(PFN_vkGetInstanceProcAddr get_instance_proc_addr = nullptr) const;
  // vkDeviceWaitIdle on the host's device: it must still work after tfmatch let go of it.
  VkResult wait_idle() const;
  // Validation messages the host's messenger received.
  const std::vector<std::string>& messages() const { return messages_; }

  VkInstance instance() const { return instance_; }
  VkPhysicalDevice physical() const { return physical_; }
  VkDevice device() const { return device_; }
  VkQueue queue() const { return queue_; }
  uint32_t queue_family() const { return family_; }

 private:
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                   VkDebugUtilsMessageTypeFlagsEXT,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data, void* user);
  VkInstance instance_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  uint32_t family_ = 0;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  std::vector<std::string> messages_;
};

}  // namespace tfm::test
