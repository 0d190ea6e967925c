// A headless Vulkan renderer that re-fits a transfer function every frame with tfmatch, inside its
// own command buffers. It owns everything: instance, device, queue, two volumes as 3D images (a
// reference field as R32_SFLOAT, and the same structure in kelvin stored as R16_UNORM codes,
// value = 240 K + 60 K * c / 65535, as renderers keep large volumes), the TF buffers its renderer
// reads, two frames in flight (command buffer and fence each). Every 8 frames the reference TF
// changes, as when a user edits it; each frame records the renderer's two views and tfmatch's
// assembly of the second field's TF (NormalEquationsRecorder), which reads the two images in place;
// when that frame's fence has signalled, the host solves the small system and records the new TF
// into the buffer the renderer samples (TfUploadRecorder). tfmatch never submits. Its last frame
// records tfmatch's residual maps, also reading the images in place. A third timing shows the
// other way in: tfmatch's device copies of the images (ImageFieldRecorder), made every frame, as
// the kernels that read only fields need.
//
// Prints frame times without and with the re-fit, checks the last fit against the same fit
// computed on the CPU and the TF buffer against the fit, and compares the two renderings before
// and after fitting. With TFMATCH_VALIDATION=1 the Khronos validation layer with synchronization
// validation watches the application's command buffers; any message fails the run.
// Exit code 0: OK; 1: a check failed; 2: no Vulkan device with a compute queue.
#include <vulkan/vulkan.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <tfmatch/engine/context.h>
#include <tfmatch/engine/device_field.h>
#include <tfmatch/model/field_mapping.h>
#include <tfmatch/solvers/normal_equations.h>
#include <tfmatch/reference/normal_equations_cpu.h>
#include <tfmatch/kernels/recording.h>
#include <tfmatch/model/transfer_function.h>

#include "march_spirv.h"

namespace {

constexpr uint32_t kNx = 72, kNy = 64, kNz = 48;  // the volumes
constexpr uint64_t kVoxels = uint64_t(kNx) * kNy * kNz;
constexpr uint32_t kRefEntries = 32, kFitEntries = 64;
constexpr uint32_t kImage = 192;  // pixels per side
constexpr int kFramesInFlight = 2;
constexpr float kExtinction = 0.35f;

struct Push {
  uint32_t nx, ny, nz, tf_size;
  float lo, scale, extinction;
  uint32_t size;
};

std::vector<std::string> g_messages;

VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT, VkDebugUtilsMessageTypeFlagsEXT,
                                          const VkDebugUtilsMessengerCallbackDataEXT* data, void*) {
  g_messages.emplace_back(data->pMessage ? data->pMessage : "(no text)");
  return VK_FALSE;
}

struct MemoryBuffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  void* mapped = nullptr;  // host-visible buffers only
};

// The application's Vulkan objects, created and destroyed by the application.
struct App {
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t family = 0;
  bool int64_atomics = false;  // enabled on the device, for tfmatch's accumulating kernels
  VkPhysicalDeviceMemoryProperties memory_properties{};
  std::vector<MemoryBuffer> buffers;
  struct MemoryImage {
    VkImage image = VK_NULL_HANDLE;
    VkImageView view = VK_NULL_HANDLE;
    VkDeviceMemory memory = VK_NULL_HANDLE;
  };
  std::vector<MemoryImage> images;

  bool create(bool validation) {
    VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
    app.pApplicationName = "tfmatch renderer example";
    app.apiVersion = VK_API_VERSION_1_2;
    const char* layer = "VK_LAYER_KHRONOS_validation";
    const char* extension = VK_EXT_DEBUG_UTILS_EXTENSION_NAME;
    VkValidationFeatureEnableEXT sync = VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT;
    VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
    features.enabledValidationFeatureCount = 1;
    features.pEnabledValidationFeatures = &sync;
    VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
    info.pApplicationInfo = &app;
    if (validation) {
      info.pNext = &features;
      info.enabledLayerCount = 1;
      info.ppEnabledLayerNames = &layer;
      info.enabledExtensionCount = 1;
      info.ppEnabledExtensionNames = &extension;
    }
    if (vkCreateInstance(&info, nullptr, &instance) != VK_SUCCESS) return false;
    if (validation) {
      VkDebugUtilsMessengerCreateInfoEXT mi{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
      mi.messageSeverity =
          VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
      mi.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT;
      mi.pfnUserCallback = &on_message;
      auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT"));
      if (!create_messenger || create_messenger(instance, &mi, nullptr, &messenger) != VK_SUCCESS) return false;
    }
    uint32_t count = 0;
    vkEnumeratePhysicalDevices(instance, &count, nullptr);
    std::vector<VkPhysicalDevice> devices(count);
    vkEnumeratePhysicalDevices(instance, &count, devices.data());
    for (VkPhysicalDevice pd : devices) {
      uint32_t n = 0;
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, nullptr);
      std::vector<VkQueueFamilyProperties> families(n);
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, families.data());
      for (uint32_t i = 0; i < n && !physical; ++i)
        if (families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) physical = pd, family = i;
      if (physical) break;
    }
    if (!physical) return false;
    const float priority = 1.0f;
    VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
    queue_info.queueFamilyIndex = family;
    queue_info.queueCount = 1;
    queue_info.pQueuePriorities = &priority;
    // 64-bit atomics where the device has them: tfmatch's assembly adds one word per slot then
    // (ExternalDevice::int64_atomics_enabled), instead of two with a carry.
    VkPhysicalDeviceVulkan12Features features12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
    VkPhysicalDeviceFeatures2 available{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2, &features12};
    vkGetPhysicalDeviceFeatures2(physical, &available);
    int64_atomics = available.features.shaderInt64 && features12.shaderBufferInt64Atomics &&
                    features12.shaderSharedInt64Atomics;
    VkPhysicalDeviceVulkan12Features enable12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
    VkPhysicalDeviceFeatures2 enable{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2, &enable12};
    enable.features.shaderInt64 = enable12.shaderBufferInt64Atomics = enable12.shaderSharedInt64Atomics = int64_atomics;
    VkDeviceCreateInfo device_info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
    device_info.pNext = &enable;
    device_info.queueCreateInfoCount = 1;
    device_info.pQueueCreateInfos = &queue_info;
    if (vkCreateDevice(physical, &device_info, nullptr, &device) != VK_SUCCESS) return false;
    vkGetDeviceQueue(device, family, 0, &queue);
    vkGetPhysicalDeviceMemoryProperties(physical, &memory_properties);
    return true;
  }

  // A buffer of `bytes`, device-local where the device has such memory, else host-visible; or
  // host-visible and mapped when `host_visible`.
  MemoryBuffer buffer(uint64_t bytes, VkBufferUsageFlags usage, bool host_visible) {
    MemoryBuffer b;
    VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    info.size = bytes;
    info.usage = usage;
    if (vkCreateBuffer(device, &info, nullptr, &b.buffer) != VK_SUCCESS) std::abort();
    VkMemoryRequirements req{};
    vkGetBufferMemoryRequirements(device, b.buffer, &req);
    const VkMemoryPropertyFlags want =
        host_visible ? VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                     : VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
    uint32_t type = 0;
    while (type < memory_properties.memoryTypeCount &&
           !((req.memoryTypeBits >> type & 1u) && (memory_properties.memoryTypes[type].propertyFlags & want) == want))
      ++type;
    if (type == memory_properties.memoryTypeCount) std::abort();
    VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    alloc.allocationSize = req.size;
    alloc.memoryTypeIndex = type;
    if (vkAllocateMemory(device, &alloc, nullptr, &b.memory) != VK_SUCCESS) std::abort();
    vkBindBufferMemory(device, b.buffer, b.memory, 0);
    if (host_visible) vkMapMemory(device, b.memory, 0, VK_WHOLE_SIZE, 0, &b.mapped);
    buffers.push_back(b);
    return b;
  }

  // A 3D image of `format` in device-local memory, sampled by the renderer's shader, written by
  // copies and read by tfmatch's copy (transfer source), with a view for the renderer.
  MemoryImage volume_image(VkFormat format, VkExtent3D extent) {
    MemoryImage m;
    VkImageCreateInfo ii{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
    ii.imageType = VK_IMAGE_TYPE_3D;
    ii.format = format;
    ii.extent = extent;
    ii.mipLevels = ii.arrayLayers = 1;
    ii.samples = VK_SAMPLE_COUNT_1_BIT;
    ii.tiling = VK_IMAGE_TILING_OPTIMAL;
    ii.usage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
    if (vkCreateImage(device, &ii, nullptr, &m.image) != VK_SUCCESS) std::abort();
    VkMemoryRequirements req{};
    vkGetImageMemoryRequirements(device, m.image, &req);
    uint32_t type = 0;
    while (type < memory_properties.memoryTypeCount &&
           !((req.memoryTypeBits >> type & 1u) &&
             (memory_properties.memoryTypes[type].propertyFlags & VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT)))
      ++type;
    if (type == memory_properties.memoryTypeCount) std::abort();
    VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    alloc.allocationSize = req.size;
    alloc.memoryTypeIndex = type;
    if (vkAllocateMemory(device, &alloc, nullptr, &m.memory) != VK_SUCCESS) std::abort();
    vkBindImageMemory(device, m.image, m.memory, 0);
    VkImageViewCreateInfo vi{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
    vi.image = m.image;
    vi.viewType = VK_IMAGE_VIEW_TYPE_3D;
    vi.format = format;
    vi.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    if (vkCreateImageView(device, &vi, nullptr, &m.view) != VK_SUCCESS) std::abort();
    images.push_back(m);
    return m;
  }

  void destroy() {
    if (device) {
      vkDeviceWaitIdle(device);
      for (MemoryImage& m : images) {
        vkDestroyImageView(device, m.view, nullptr);
        vkDestroyImage(device, m.image, nullptr);
        vkFreeMemory(device, m.memory, nullptr);
      }
      for (MemoryBuffer& b : buffers) {
        vkDestroyBuffer(device, b.buffer, nullptr);
        vkFreeMemory(device, b.memory, nullptr);
      }
      vkDestroyDevice(device, nullptr);
    }
    if (messenger) {
      auto destroy_messenger = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
      destroy_messenger(instance, messenger, nullptr);
    }
    if (instance) vkDestroyInstance(instance, nullptr);
  }
};

// Records the copy of `staging` from `offset` into all of `image` (extent `extent`), from
// UNDEFINED through TRANSFER_DST_OPTIMAL to SHADER_READ_ONLY_OPTIMAL, where the renderer's compute
// shader samples it.
void upload_image(VkCommandBuffer cmd, VkBuffer staging, uint64_t offset, VkImage image, VkExtent3D extent) {
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image;
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0, nullptr,
                       1, &b);
  VkBufferImageCopy region{};
  region.bufferOffset = offset;
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = extent;
  vkCmdCopyBufferToImage(cmd, staging, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 0, nullptr, 0,
                       nullptr, 1, &b);
}

void memory_barrier(VkCommandBuffer cmd, VkPipelineStageFlags src_stages, VkAccessFlags src_access,
                    VkPipelineStageFlags dst_stages, VkAccessFlags dst_access) {
  VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  b.srcAccessMask = src_access;
  b.dstAccessMask = dst_access;
  vkCmdPipelineBarrier(cmd, src_stages, dst_stages, 0, 1, &b, 0, nullptr, 0, nullptr);
}

// The reference field: smooth blobs in [0, 1]. The second field: the same structure in other
// units through a monotone nonlinear map, so one TF explains it and the fit can match exactly.
void make_fields(std::vector<float>& ref, std::vector<uint16_t>& opt) {
  ref.resize(kVoxels);
  opt.resize(kVoxels);
  const std::array<std::array<double, 4>, 3> blobs{
      {{0.3, 0.4, 0.5, 0.18}, {0.7, 0.6, 0.4, 0.14}, {0.5, 0.25, 0.7, 0.1}}};  // centre, width
  for (uint32_t z = 0; z < kNz; ++z)
    for (uint32_t y = 0; y < kNy; ++y)
      for (uint32_t x = 0; x < kNx; ++x) {
        const double p[3] = {(x + 0.5) / kNx, (y + 0.5) / kNy, (z + 0.5) / kNz};
        double v = 0.0;
        for (const auto& b : blobs) {
          double d2 = 0.0;
          for (int a = 0; a < 3; ++a) d2 += (p[a] - b[a]) * (p[a] - b[a]);
          v += std::exp(-d2 / (2 * b[3] * b[3]));
        }
        const uint64_t i = (uint64_t(z) * kNy + y) * kNx + x;
        ref[i] = float(std::min(v, 1.0));
        opt[i] = uint16_t(std::lround(65535.0 * std::pow(double(ref[i]), 1.6)));  // 240 + 60 c / 65535 K
      }
}

// The reference TF the user edits: a colour ramp whose hue and opacity peak move with `phase`.
tfm::TransferFunction reference_tf(int phase) {
  tfm::TransferFunction tf;
  const double peak = 0.35 + 0.15 * (phase % 4);
  for (uint32_t j = 0; j < kRefEntries; ++j) {
    const double t = j / double(kRefEntries - 1);
    const double hue = std::fmod(t + 0.23 * phase, 1.0);
    tf.rgba.push_back({0.5 + 0.5 * std::cos(6.283 * hue), 0.5 + 0.5 * std::cos(6.283 * (hue - 0.33)),
                       0.5 + 0.5 * std::cos(6.283 * (hue - 0.67)), 0.9 * std::exp(-(t - peak) * (t - peak) / 0.02)});
  }
  return tf;
}

// Mean absolute difference of two RGBA8 images, in 8-bit steps per channel.
double image_difference(const uint32_t* a, const uint32_t* b) {
  double sum = 0.0;
  for (uint32_t i = 0; i < kImage * kImage; ++i)
    for (int c = 0; c < 4; ++c) sum += std::abs(int(a[i] >> (8 * c) & 255u) - int(b[i] >> (8 * c) & 255u));
  return sum / (4.0 * kImage * kImage);
}

}  // namespace

int main() {
  const char* env = std::getenv("TFMATCH_VALIDATION");
  const bool validation = env && std::string(env) == "1";
  App app;
  if (!app.create(validation)) {
    std::fprintf(stderr, "renderer_example: no Vulkan device with a compute queue%s\n",
                 validation ? " (or no validation layer)" : "");
    app.destroy();
    return 2;
  }
  int status = 0;
  {
    tfm::ExternalDevice lent{app.instance, app.physical, app.device, app.queue, app.family};
    lent.api_version = VK_API_VERSION_1_2;  // what the instance was created with
    lent.int64_atomics_enabled = app.int64_atomics;
    auto ctx = tfm::Context::adopt(lent);

    // The application's resources: volumes as 3D images (sampled by its renderer, copied on the
    // device by tfmatch), TF buffers its renderer reads (tfmatch writes the fitted one), two
    // pictures.
    std::vector<float> ref;
    std::vector<uint16_t> opt;
    make_fields(ref, opt);
    const VkExtent3D extent{kNx, kNy, kNz};
    const App::MemoryImage ref_volume = app.volume_image(VK_FORMAT_R32_SFLOAT, extent);
    const App::MemoryImage opt_volume = app.volume_image(VK_FORMAT_R16_UNORM, extent);
    const MemoryBuffer staging = app.buffer(kVoxels * 6, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, true);
    std::memcpy(staging.mapped, ref.data(), kVoxels * 4);
    std::memcpy(static_cast<char*>(staging.mapped) + kVoxels * 4, opt.data(), kVoxels * 2);
    const VkBufferUsageFlags tf_usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    const VkBuffer ref_tf_buffer = app.buffer(kRefEntries * 16, tf_usage, false).buffer;
    const MemoryBuffer fit_tf_buffer = app.buffer(kFitEntries * 16, tf_usage, true);
    const MemoryBuffer ref_image = app.buffer(kImage * kImage * 4, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, true);
    const MemoryBuffer opt_image = app.buffer(kImage * kImage * 4, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, true);
    // Before any fit the second field is shown with a grey ramp.
    for (uint32_t j = 0; j < kFitEntries; ++j) {
      const float t = j / float(kFitEntries - 1);
      const float e[4] = {t, t, t, 0.5f * t};
      std::memcpy(static_cast<char*>(fit_tf_buffer.mapped) + 16 * j, e, 16);
    }

    // The renderer's pipeline and its two descriptor sets (reference view, second view).
    VkShaderModuleCreateInfo mi{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
    mi.codeSize = sizeof(march_spirv);
    mi.pCode = march_spirv;
    VkShaderModule module = VK_NULL_HANDLE;
    vkCreateShaderModule(app.device, &mi, nullptr, &module);
    VkDescriptorSetLayoutBinding bindings[3];
    for (uint32_t i = 0; i < 3; ++i)
      bindings[i] = {i, i == 0 ? VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1,
                     VK_SHADER_STAGE_COMPUTE_BIT, nullptr};
    VkDescriptorSetLayoutCreateInfo li{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
    li.bindingCount = 3;
    li.pBindings = bindings;
    VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
    vkCreateDescriptorSetLayout(app.device, &li, nullptr, &set_layout);
    VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(Push)};
    VkPipelineLayoutCreateInfo pli{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
    pli.setLayoutCount = 1;
    pli.pSetLayouts = &set_layout;
    pli.pushConstantRangeCount = 1;
    pli.pPushConstantRanges = &range;
    VkPipelineLayout layout = VK_NULL_HANDLE;
    vkCreatePipelineLayout(app.device, &pli, nullptr, &layout);
    VkComputePipelineCreateInfo ci{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
    ci.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO, nullptr, 0, VK_SHADER_STAGE_COMPUTE_BIT, module,
                "main", nullptr};
    ci.layout = layout;
    VkPipeline pipeline = VK_NULL_HANDLE;
    vkCreateComputePipelines(app.device, VK_NULL_HANDLE, 1, &ci, nullptr, &pipeline);
    const VkDescriptorPoolSize pool_sizes[2] = {{VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE, 2},
                                                {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 4}};
    VkDescriptorPoolCreateInfo dpi{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    dpi.maxSets = 2;
    dpi.poolSizeCount = 2;
    dpi.pPoolSizes = pool_sizes;
    VkDescriptorPool descriptor_pool = VK_NULL_HANDLE;
    vkCreateDescriptorPool(app.device, &dpi, nullptr, &descriptor_pool);
    VkDescriptorSet sets[2];
    const VkDescriptorSetLayout set_layouts[2] = {set_layout, set_layout};
    VkDescriptorSetAllocateInfo dai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    dai.descriptorPool = descriptor_pool;
    dai.descriptorSetCount = 2;
    dai.pSetLayouts = set_layouts;
    vkAllocateDescriptorSets(app.device, &dai, sets);
    const VkImageView set_volumes[2] = {ref_volume.view, opt_volume.view};
    const VkBuffer set_buffers[2][2] = {{ref_tf_buffer, ref_image.buffer}, {fit_tf_buffer.buffer, opt_image.buffer}};
    for (int s = 0; s < 2; ++s)
      for (uint32_t i = 0; i < 3; ++i) {
        const VkDescriptorImageInfo ii{VK_NULL_HANDLE, set_volumes[s], VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
        const VkDescriptorBufferInfo bi{i ? set_buffers[s][i - 1] : VK_NULL_HANDLE, 0, VK_WHOLE_SIZE};
        VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
        w.dstSet = sets[s];
        w.dstBinding = i;
        w.descriptorCount = 1;
        w.descriptorType = bindings[i].descriptorType;
        if (i == 0)
          w.pImageInfo = &ii;
        else
          w.pBufferInfo = &bi;
        vkUpdateDescriptorSets(app.device, 1, &w, 0, nullptr);
      }

    // Frames in flight: a command buffer, a fence, and tfmatch's recorders for each.
    VkCommandPoolCreateInfo cpi{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
    cpi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    cpi.queueFamilyIndex = app.family;
    VkCommandPool command_pool = VK_NULL_HANDLE;
    vkCreateCommandPool(app.device, &cpi, nullptr, &command_pool);
    VkCommandBuffer cmds[kFramesInFlight];
    VkCommandBufferAllocateInfo cai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    cai.commandPool = command_pool;
    cai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    cai.commandBufferCount = kFramesInFlight;
    vkAllocateCommandBuffers(app.device, &cai, cmds);
    VkFence fences[kFramesInFlight];
    VkFenceCreateInfo fi{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    fi.flags = VK_FENCE_CREATE_SIGNALED_BIT;
    for (VkFence& f : fences) vkCreateFence(app.device, &fi, nullptr, &f);
    struct Slot {
      std::unique_ptr<tfm::NormalEquationsRecorder> recorder;
      std::unique_ptr<tfm::TfUploadRecorder> uploader;
      bool assembled = false;
      tfm::TransferFunction assembled_tf;  // the reference TF that assembly used
    };
    Slot slots[kFramesInFlight];
    for (Slot& s : slots) {
      s.recorder = std::make_unique<tfm::NormalEquationsRecorder>(*ctx, kFitEntries);
      s.uploader = std::make_unique<tfm::TfUploadRecorder>(*ctx);
    }

    auto begin = [&](VkCommandBuffer cmd) {
      vkResetCommandBuffer(cmd, 0);
      VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
      bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
      vkBeginCommandBuffer(cmd, &bi);
    };
    auto submit = [&](VkCommandBuffer cmd, VkFence fence) {
      vkEndCommandBuffer(cmd);
      VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
      si.commandBufferCount = 1;
      si.pCommandBuffers = &cmd;
      vkQueueSubmit(app.queue, 1, &si, fence);
    };

    // The volumes go up once, and tfmatch copies them on the device into its fields in the same
    // command buffer (the images stay the renderer's, in SHADER_READ_ONLY_OPTIMAL).
    tfm::ImageFieldRecorder ref_copy(*ctx, extent, VK_FORMAT_R32_SFLOAT, "reference volume");
    tfm::ImageFieldRecorder opt_copy(*ctx, extent, VK_FORMAT_R16_UNORM, "second volume");
    vkWaitForFences(app.device, 1, &fences[0], VK_TRUE, UINT64_MAX);
    vkResetFences(app.device, 1, &fences[0]);
    begin(cmds[0]);
    upload_image(cmds[0], staging.buffer, 0, ref_volume.image, extent);
    upload_image(cmds[0], staging.buffer, kVoxels * 4, opt_volume.image, extent);
    tfm::ImageFieldSource source;  // the renderer's last write: the upload; its next use: its shader
    source.extent = extent;
    source.image = ref_volume.image;
    source.format = VK_FORMAT_R32_SFLOAT;
    ref_copy.record_copy(cmds[0], source);
    source.image = opt_volume.image;
    source.format = VK_FORMAT_R16_UNORM;
    opt_copy.record_copy(cmds[0], source);
    submit(cmds[0], fences[0]);
    const tfm::DeviceField& ref_field = ref_copy.field();
    const tfm::DeviceField& opt_field = opt_copy.field();
    const tfm::FieldRange ref_range{0.0, 1.0}, opt_range{240.0, 300.0};  // kelvin
    const tfm::ValueMapping kelvin{60.0, 240.0};                          // of the unorm16 codes
    const tfm::FieldMapping ref_map = tfm::make_mapping(ref_range, kRefEntries);
    const tfm::FieldMapping opt_map = tfm::make_mapping(opt_range, kFitEntries, kelvin);
    tfm::SolveOptions solve;
    solve.smooth = 1e-4;  // entries no voxel reaches follow their neighbours

    std::vector<float> fitted;      // the newest fit not yet written into the renderer's TF buffer
    std::vector<float> last_fit;    // the newest fit solved
    tfm::TransferFunction last_fit_reference;
    double difference_before = -1.0;
    const uint64_t submissions_before = ctx->submissions();

    // Runs `frames` frames; returns the mean wall time of a frame in ms.
    auto run = [&](int frames, bool refit, bool copy = false) {
      const auto start = std::chrono::steady_clock::now();
      tfm::TransferFunction ref_tf;
      for (int k = 0; k < frames; ++k) {
        const int s = k % kFramesInFlight;
        Slot& slot = slots[s];
        vkWaitForFences(app.device, 1, &fences[s], VK_TRUE, UINT64_MAX);
        vkResetFences(app.device, 1, &fences[s]);
        if (slot.assembled) {  // that frame's fit: solve the small system on the host
          const tfm::SolveResult result = tfm::solve_normal_equations(slot.recorder->result(), solve);
          fitted = last_fit = result.tf.as_floats();
          last_fit_reference = slot.assembled_tf;
          slot.assembled = false;
        }
        if (difference_before < 0.0 && k == 2)  // frame 0's images, with the grey ramp
          difference_before = image_difference(static_cast<const uint32_t*>(ref_image.mapped),
                                               static_cast<const uint32_t*>(opt_image.mapped));
        const bool ref_changed = k % 8 == 0;
        if (ref_changed) ref_tf = reference_tf(k / 8);
        const std::vector<float> ref_floats = ref_tf.as_floats();

        VkCommandBuffer cmd = cmds[s];
        begin(cmd);
        // Writes to the TF buffers wait for the renders of earlier frames still reading them.
        memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT, 0);
        if (ref_changed) vkCmdUpdateBuffer(cmd, ref_tf_buffer, 0, ref_floats.size() * 4, ref_floats.data());
        if (!fitted.empty()) {
          slot.uploader->record_tf_upload(cmd, fitted, tfm::TfBufferTarget{fit_tf_buffer.buffer, 0, kFitEntries * 16});
          fitted.clear();
        }
        memory_barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
        // The renderer's two views (each image is written by one frame at a time: the other
        // frame's writes finish first).
        memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT);
        vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline);
        const Push pushes[2] = {{kNx, kNy, kNz, kRefEntries, ref_map.lo, ref_map.scale, kExtinction, kImage},
                                {kNx, kNy, kNz, kFitEntries, opt_map.lo, opt_map.scale, kExtinction, kImage}};
        for (int v = 0; v < 2; ++v) {
          vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout, 0, 1, &sets[v], 0, nullptr);
          vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(Push), &pushes[v]);
          vkCmdDispatch(cmd, (kImage + 7) / 8, (kImage + 7) / 8, 1);
        }
        memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                       VK_ACCESS_HOST_READ_BIT);
        // tfmatch's part of the frame: the fit of the second field's TF to the current reference TF.
        if (copy) {  // device copies, as when the volumes change every frame (a time series playing)
          source.image = ref_volume.image;
          source.format = VK_FORMAT_R32_SFLOAT;
          source.src_stages = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;  // the renderer's reads above
          source.src_access = 0;
          ref_copy.record_copy(cmd, source);
          source.image = opt_volume.image;
          source.format = VK_FORMAT_R16_UNORM;
          opt_copy.record_copy(cmd, source);
        }
        if (refit) {
          if (copy) {
            slot.recorder->record_assemble(cmd, ref_field, opt_field, ref_map, opt_map, ref_floats);
          } else {  // the renderer's images read in place
            const VkImageLayout sampled = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
            const tfm::ImageFieldView ref_image{ref_volume.view, sampled, extent, VK_FORMAT_R32_SFLOAT};
            const tfm::ImageFieldView opt_image{opt_volume.view, sampled, extent, VK_FORMAT_R16_UNORM};
            slot.recorder->record_assemble(cmd, ref_image, opt_image, ref_map, opt_map, ref_floats);
          }
          slot.assembled = true;
          slot.assembled_tf = ref_tf;
        }
        submit(cmd, fences[s]);
      }
      vkWaitForFences(app.device, kFramesInFlight, fences, VK_TRUE, UINT64_MAX);
      return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() / frames;
    };

    // A few frames first: tfmatch builds its pipelines on the first recording of each recorder
    // (lavapipe compiles them in hundreds of ms), as the renderer's own are built before it runs.
    run(2 * kFramesInFlight, true);
    const int frames = 48;
    const double plain_ms = run(frames, false);
    const double refit_ms = run(frames, true);
    const double copy_ms = run(frames, true, true);
    std::printf("%d frames of 2 views %ux%u of %ux%ux%u voxels (3D images R32F and R16) on %s "
                "(%s-bit atomics for tfmatch):\n",
                frames, kImage, kImage, kNx, kNy, kNz, ctx->device_name().c_str(), app.int64_atomics ? "64" : "32");
    std::printf("  without re-fit: %.2f ms a frame\n  with the TF re-fit recorded into each frame (images read in place): "
                "%.2f ms a frame\n",
                plain_ms, refit_ms);
    std::printf("  with the re-fit on tfmatch's device copies of both images, made each frame: %.2f ms a frame\n", copy_ms);
    if (ctx->submissions() != submissions_before) {
      std::printf("FAILED: tfmatch submitted %llu times while recording\n",
                  static_cast<unsigned long long>(ctx->submissions() - submissions_before));
      status = 1;
    }

    // The last fit goes into the renderer's TF buffer in one more frame; then the checks.
    for (Slot& slot : slots)
      if (slot.assembled) {
        last_fit = tfm::solve_normal_equations(slot.recorder->result(), solve).tf.as_floats();
        last_fit_reference = slot.assembled_tf;
        slot.assembled = false;
      }
    // The same frame records tfmatch's residual maps of the second field (what its TF cannot
    // explain, DESIGN.md) into the renderer's buffers, under the grey ramp and under the fit: a
    // renderer shows such a field as a third volume.
    const VkBufferUsageFlags field_usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT;
    const MemoryBuffer residual_before = app.buffer(kVoxels * 4, field_usage, true);
    const MemoryBuffer residual_after = app.buffer(kVoxels * 4, field_usage, true);
    tfm::DeviceField residual_before_field =
        tfm::DeviceField::adopt(*ctx, residual_before.buffer, 0, kVoxels, "residual, grey ramp");
    tfm::DeviceField residual_after_field =
        tfm::DeviceField::adopt(*ctx, residual_after.buffer, 0, kVoxels, "residual, fit");
    std::vector<float> grey_ramp(kFitEntries * 4);
    for (uint32_t j = 0; j < kFitEntries; ++j) {
      const float t = j / float(kFitEntries - 1);
      grey_ramp[4 * j] = grey_ramp[4 * j + 1] = grey_ramp[4 * j + 2] = t;
      grey_ramp[4 * j + 3] = 0.5f * t;
    }
    tfm::ResidualMapRecorder residual_recorder_before(*ctx), residual_recorder_after(*ctx);
    const std::vector<float> last_reference_floats = last_fit_reference.as_floats();
    vkResetFences(app.device, 1, &fences[0]);
    begin(cmds[0]);
    memory_barrier(cmds[0], VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT, 0);
    slots[0].uploader->record_tf_upload(cmds[0], last_fit, tfm::TfBufferTarget{fit_tf_buffer.buffer, 0, kFitEntries * 16});
    const tfm::ImageFieldView ref_in_place{ref_volume.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, extent,
                                           VK_FORMAT_R32_SFLOAT};
    const tfm::ImageFieldView opt_in_place{opt_volume.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, extent,
                                           VK_FORMAT_R16_UNORM};
    residual_recorder_before.record_residual_map(cmds[0], ref_in_place, opt_in_place, ref_map, opt_map,
                                                 last_reference_floats, grey_ramp, residual_before_field);
    residual_recorder_after.record_residual_map(cmds[0], ref_in_place, opt_in_place, ref_map, opt_map,
                                                last_reference_floats, last_fit, residual_after_field);
    memory_barrier(cmds[0], VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                   VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                   VK_ACCESS_HOST_READ_BIT);
    submit(cmds[0], fences[0]);
    vkWaitForFences(app.device, 1, &fences[0], VK_TRUE, UINT64_MAX);
    if (std::memcmp(fit_tf_buffer.mapped, last_fit.data(), last_fit.size() * 4) != 0) {
      std::printf("FAILED: the renderer's TF buffer does not hold the fit\n");
      status = 1;
    }
    // The same fit on the CPU: double-precision assembly (tfmatch's reference) and the same solve.
    // The CPU sees the codes as the stored numbers c / 65535 (the device may round them
    // differently by an ulp: within the check's bound).
    std::vector<float> opt_stored(kVoxels);
    for (uint64_t i = 0; i < kVoxels; ++i) opt_stored[i] = float(opt[i]) / 65535.0f;
    const tfm::NormalEquations cpu =
        tfm::assemble_normal_equations_cpu(ref, opt_stored, ref_map, opt_map, last_fit_reference);
    const std::vector<float> cpu_fit = tfm::solve_normal_equations(cpu, solve).tf.as_floats();
    double worst = 0.0;
    for (size_t i = 0; i < cpu_fit.size(); ++i) worst = std::max(worst, double(std::abs(cpu_fit[i] - last_fit[i])));
    std::printf("  last fit against the CPU's: max |difference| %.2e over %u entries\n", worst, kFitEntries);
    if (!(worst <= 1e-4)) {
      std::printf("FAILED: the GPU fit differs from the CPU fit\n");
      status = 1;
    }
    auto mean_of = [](const MemoryBuffer& b) {
      const float* v = static_cast<const float*>(b.mapped);
      double sum = 0.0;
      for (uint64_t i = 0; i < kVoxels; ++i) sum += v[i];
      return sum / double(kVoxels);
    };
    const double residual_grey = mean_of(residual_before), residual_fit = mean_of(residual_after);
    std::printf("  residual map (tfmatch, into the renderer's buffers): mean %.4f (grey ramp) -> %.4f (fitted TF)\n",
                residual_grey, residual_fit);
    if (!(residual_fit < 0.1 * residual_grey)) {
      std::printf("FAILED: the fitted TF leaves a residual a single TF should explain\n");
      status = 1;
    }
    const double difference_after = image_difference(static_cast<const uint32_t*>(ref_image.mapped),
                                                     static_cast<const uint32_t*>(opt_image.mapped));
    std::printf("  the two views differ by %.2f (grey ramp) -> %.2f (fitted TF) of 255 per channel\n",
                difference_before, difference_after);
    if (!(difference_after < 0.25 * difference_before)) {
      std::printf("FAILED: the fitted TF does not make the second view match the reference view\n");
      status = 1;
    }

    vkDeviceWaitIdle(app.device);
    for (VkFence f : fences) vkDestroyFence(app.device, f, nullptr);
    vkDestroyCommandPool(app.device, command_pool, nullptr);
    vkDestroyDescriptorPool(app.device, descriptor_pool, nullptr);
    vkDestroyPipeline(app.device, pipeline, nullptr);
    vkDestroyPipelineLayout(app.device, layout, nullptr);
    vkDestroyDescriptorSetLayout(app.device, set_layout, nullptr);
    vkDestroyShaderModule(app.device, module, nullptr);
  }  // tfmatch lets go of the device here, before the application destroys it
  app.destroy();
  for (const std::string& m : g_messages) std::printf("validation: %s\n", m.c_str());
  if (!g_messages.empty()) status = 1;
  std::printf(status == 0 ? "OK\n" : "FAILED\n");
  return status;
}
