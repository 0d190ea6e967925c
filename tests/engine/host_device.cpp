// The embedding tests' host: one source, compiled against the loader's prototypes or (with
// TFM_TEST_HOST_USES_VOLK) against the host's own volk, whose globals then carry every call.
#ifdef TFM_TEST_HOST_USES_VOLK
#include <volk.h>
#else
#include <vulkan/vulkan.h>
#endif

#include "host_device.h"

#include <cstdlib>
#include <cstring>

#include <gtest/gtest.h>

namespace tfm::test {

VKAPI_ATTR VkBool32 VKAPI_CALL HostDevice::on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                      VkDebugUtilsMessageTypeFlagsEXT,
                                                      const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                      void* user) {
  static_cast<HostDevice*>(user)->messages_.push_back(data && data->pMessage ? data->pMessage : "(no message)");
  return VK_FALSE;
}

void HostDevice::create() {
#ifdef TFM_TEST_HOST_USES_VOLK
  ASSERT_EQ(volkInitialize(), VK_SUCCESS);
#endif
  const char* layer = "VK_LAYER_KHRONOS_validation";
  uint32_t count = 0;
  ASSERT_EQ(vkEnumerateInstanceLayerProperties(&count, nullptr), VK_SUCCESS);
  std::vector<VkLayerProperties> layers(count);
  ASSERT_EQ(vkEnumerateInstanceLayerProperties(&count, layers.data()), VK_SUCCESS);
  bool validation = false;
  for (auto& l : layers) validation |= std::strcmp(l.layerName, layer) == 0;
  const char* env = std::getenv("TFMATCH_VALIDATION");
  if (env && std::string(env) == "1") ASSERT_TRUE(validation) << layer << " requested but not installed";

  const char* ext = VK_EXT_DEBUG_UTILS_EXTENSION_NAME;
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.apiVersion = VK_API_VERSION_1_2;
  VkValidationFeatureEnableEXT enables[] = {VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT};
  VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
  features.enabledValidationFeatureCount = 1;
  features.pEnabledValidationFeatures = enables;
  VkInstanceCreateInfo ii{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  ii.pNext = validation ? &features : nullptr;
  ii.pApplicationInfo = &app;
  ii.enabledLayerCount = validation ? 1 : 0;
  ii.ppEnabledLayerNames = &layer;
  ii.enabledExtensionCount = 1;
  ii.ppEnabledExtensionNames = &ext;
  ASSERT_EQ(vkCreateInstance(&ii, nullptr, &instance_), VK_SUCCESS);
#ifdef TFM_TEST_HOST_USES_VOLK
  volkLoadInstance(instance_);
#endif

  VkDebugUtilsMessengerCreateInfoEXT mi{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
  mi.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  mi.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT;
  mi.pfnUserCallback = &HostDevice::on_message;
  mi.pUserData = this;
#ifdef TFM_TEST_HOST_USES_VOLK
  auto create_messenger = vkCreateDebugUtilsMessengerEXT;
#else  // an instance extension: the loader does not export it
  auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
      vkGetInstanceProcAddr(instance_, "vkCreateDebugUtilsMessengerEXT"));
#endif
  ASSERT_NE(create_messenger, nullptr);
  ASSERT_EQ(create_messenger(instance_, &mi, nullptr, &messenger_), VK_SUCCESS);

  uint32_t n = 1;
  VkResult r = vkEnumeratePhysicalDevices(instance_, &n, &physical_);
  ASSERT_TRUE((r == VK_SUCCESS || r == VK_INCOMPLETE) && n == 1);
  uint32_t fc = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(physical_, &fc, nullptr);
  std::vector<VkQueueFamilyProperties> families(fc);
  vkGetPhysicalDeviceQueueFamilyProperties(physical_, &fc, families.data());
  while (family_ < fc && !(families[family_].queueFlags & VK_QUEUE_COMPUTE_BIT)) ++family_;
  ASSERT_LT(family_, fc);
  float priority = 1.0f;
  VkDeviceQueueCreateInfo qi{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  qi.queueFamilyIndex = family_;
  qi.queueCount = 1;
  qi.pQueuePriorities = &priority;
  VkDeviceCreateInfo di{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  di.queueCreateInfoCount = 1;
  di.pQueueCreateInfos = &qi;
  ASSERT_EQ(vkCreateDevice(physical_, &di, nullptr, &device_), VK_SUCCESS);
#ifdef TFM_TEST_HOST_USES_VOLK
  volkLoadDevice(device_);
#endif
  vkGetDeviceQueue(device_, family_, 0, &queue_);
}

ExternalDevice HostDevice::external(PFN_vkGetInstanceProcAddr get_instance_proc_addr) const {
  ExternalDevice external{instance_, physical_, device_, queue_, family_, get_instance_proc_addr};
  external.api_version = VK_API_VERSION_1_2;  // as the instance above was made
  return external;
}

VkResult HostDevice::wait_idle() const { return vkDeviceWaitIdle(device_); }

HostDevice::~HostDevice() {
  if (device_) vkDestroyDevice(device_, nullptr);
  if (messenger_) {
#ifdef TFM_TEST_HOST_USES_VOLK
    auto destroy_messenger = vkDestroyDebugUtilsMessengerEXT;
#else
    auto destroy_messenger = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
#endif
    destroy_messenger(instance_, messenger_, nullptr);
  }
  if (instance_) vkDestroyInstance(instance_, nullptr);
}

}  // namespace tfm::test
