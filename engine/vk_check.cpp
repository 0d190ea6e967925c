// VkResult names and the error thrown by VK_CHECK.
#include "tfmatch/engine/vk_check.h"

namespace tfm {

std::string vk_result_name(VkResult result) {
  switch (result) {
#define TFM_RESULT_CASE(r) case r: return #r;
    TFM_RESULT_CASE(VK_SUCCESS)
    TFM_RESULT_CASE(VK_NOT_READY)
    TFM_RESULT_CASE(VK_TIMEOUT)
    TFM_RESULT_CASE(VK_EVENT_SET)
    TFM_RESULT_CASE(VK_EVENT_RESET)
    TFM_RESULT_CASE(VK_INCOMPLETE)
    TFM_RESULT_CASE(VK_ERROR_OUT_OF_HOST_MEMORY)
    TFM_RESULT_CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    TFM_RESULT_CASE(VK_ERROR_INITIALIZATION_FAILED)
    TFM_RESULT_CASE(VK_ERROR_DEVICE_LOST)
    TFM_RESULT_CASE(VK_ERROR_MEMORY_MAP_FAILED)
    TFM_RESULT_CASE(VK_ERROR_LAYER_NOT_PRESENT)
    TFM_RESULT_CASE(VK_ERROR_EXTENSION_NOT_PRESENT)
    TFM_RESULT_CASE(VK_ERROR_FEATURE_NOT_PRESENT)
    TFM_RESULT_CASE(VK_ERROR_INCOMPATIBLE_DRIVER)
    TFM_RESULT_CASE(VK_ERROR_TOO_MANY_OBJECTS)
    TFM_RESULT_CASE(VK_ERROR_FORMAT_NOT_SUPPORTED)
    TFM_RESULT_CASE(VK_ERROR_FRAGMENTED_POOL)
    TFM_RESULT_CASE(VK_ERROR_UNKNOWN)
    TFM_RESULT_CASE(VK_ERROR_OUT_OF_POOL_MEMORY)
    TFM_RESULT_CASE(VK_ERROR_INVALID_EXTERNAL_HANDLE)
    TFM_RESULT_CASE(VK_ERROR_FRAGMENTATION)
    TFM_RESULT_CASE(VK_ERROR_INVALID_OPAQUE_CAPTURE_ADDRESS)
    TFM_RESULT_CASE(VK_ERROR_VALIDATION_FAILED_EXT)
#undef TFM_RESULT_CASE
    default: return "VkResult(" + std::to_string(static_cast<int>(result)) + ")";
  }
}

void throw_vk_error(const char* call, VkResult result, const char* file, int line) {
  throw VulkanError(std::string(call) + " failed with " + vk_result_name(result) + " at " + file +
                        ":" + std::to_string(line),
                    result);
}

}  // namespace tfm
