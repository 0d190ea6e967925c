// Loading the loader and one context's entry points (engine/vk_dispatch.h).
#include "tfmatch/engine/vk_dispatch.h"

#include <mutex>

#include "tfmatch/engine/vk_check.h"

namespace tfm {

PFN_vkGetInstanceProcAddr loader_get_instance_proc_addr() {
  static const VkResult result = volkInitialize();
  if (result != VK_SUCCESS)
    throw VulkanError("no Vulkan loader found (install libvulkan1 and a driver such as "
                      "mesa-vulkan-drivers): volkInitialize returned " + vk_result_name(result),
                      result);
  // Written once by volkInitialize above, never again: tfmatch does not call volkInitializeCustom.
  return ::vkGetInstanceProcAddr;
}

namespace {
template <class F>
void load(F& f, PFN_vkGetInstanceProcAddr get, VkInstance instance, const char* name) {
  f = reinterpret_cast<F>(get(instance, name));
}
}  // namespace

void load_instance_functions(Dispatch& d, PFN_vkGetInstanceProcAddr get, VkInstance instance) {
  d.vkGetInstanceProcAddr = get;
  load(d.vkGetDeviceProcAddr, get, instance, "vkGetDeviceProcAddr");
  load(d.vkDestroyInstance, get, instance, "vkDestroyInstance");
  load(d.vkEnumeratePhysicalDevices, get, instance, "vkEnumeratePhysicalDevices");
  load(d.vkGetPhysicalDeviceProperties, get, instance, "vkGetPhysicalDeviceProperties");
  load(d.vkGetPhysicalDeviceProperties2, get, instance, "vkGetPhysicalDeviceProperties2");
  load(d.vkGetPhysicalDeviceFeatures, get, instance, "vkGetPhysicalDeviceFeatures");
  load(d.vkGetPhysicalDeviceFeatures2, get, instance, "vkGetPhysicalDeviceFeatures2");
  load(d.vkGetPhysicalDeviceMemoryProperties, get, instance, "vkGetPhysicalDeviceMemoryProperties");
  load(d.vkGetPhysicalDeviceFormatProperties, get, instance, "vkGetPhysicalDeviceFormatProperties");
  load(d.vkGetPhysicalDeviceQueueFamilyProperties, get, instance, "vkGetPhysicalDeviceQueueFamilyProperties");
  load(d.vkEnumerateDeviceExtensionProperties, get, instance, "vkEnumerateDeviceExtensionProperties");
  load(d.vkCreateDevice, get, instance, "vkCreateDevice");
  load(d.vkCreateDebugUtilsMessengerEXT, get, instance, "vkCreateDebugUtilsMessengerEXT");
  load(d.vkDestroyDebugUtilsMessengerEXT, get, instance, "vkDestroyDebugUtilsMessengerEXT");
  load(d.vkSetDebugUtilsObjectNameEXT, get, instance, "vkSetDebugUtilsObjectNameEXT");
  if (!d.vkGetDeviceProcAddr)
    throw VulkanError("vkGetInstanceProcAddr resolved no vkGetDeviceProcAddr for the instance",
                      VK_ERROR_INITIALIZATION_FAILED);
}

void load_device_functions(Dispatch& d, VkDevice device) {
  // volkLoadDeviceTable resolves through volk's global vkGetDeviceProcAddr. That global is
  // tfmatch's own renamed copy, never a host's, so it may point at this context's resolver while
  // the table loads; the lock keeps contexts created on several threads apart.
  static std::mutex mutex;
  std::lock_guard lock(mutex);
  ::vkGetDeviceProcAddr = d.vkGetDeviceProcAddr;
  volkLoadDeviceTable(&d, device);
}

}  // namespace tfm
