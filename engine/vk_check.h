// Always-on Vulkan result checking: every failing call names itself, its VkResult and file:line.
#pragma once

#include <stdexcept>
#include <string>

#include <vulkan/vulkan_core.h>

namespace tfm {

// Thrown for any Vulkan failure (device lost, out of memory, missing feature, ...).
class VulkanError : public std::runtime_error {
 public:
  VulkanError(const std::string& what, VkResult result) : std::runtime_error(what), result_(result) {}
  VkResult result() const { return result_; }

 private:
  VkResult result_;
};

// Name of a VkResult ("VK_ERROR_DEVICE_LOST"), or its number when unknown.
std::string vk_result_name(VkResult result);

[[noreturn]] void throw_vk_error(const char* call, VkResult result, const char* file, int line);

}  // namespace tfm

#define VK_CHECK(call)                                                          \
  do {                                                                          \
    VkResult vk_check_result_ = (call);                                         \
    if (vk_check_result_ != VK_SUCCESS)                                         \
      ::tfm::throw_vk_error(#call, vk_check_result_, __FILE__, __LINE__);       \
  } while (0)
