// Instance/device creation, device selection, adoption of host handles, validation capture.
#include "tfmatch/engine/context.h"

#include <algorithm>
#include <charconv>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "tfmatch/engine/pipeline.h"
#include "tfmatch/engine/vk_check.h"
#include "tfmatch/engine/vk_dispatch.h"
#include "tfmatch/model/phase_timer.h"

namespace tfm {

std::optional<uint32_t> parse_device_index(const std::string& text, const std::string& source) {
  if (text.empty() || !std::all_of(text.begin(), text.end(), [](unsigned char c) { return std::isdigit(c); }))
    return std::nullopt;
  uint64_t index = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), index);
  if (error != std::errc() || end != text.data() + text.size() || index > UINT32_MAX)
    throw DeviceChoiceError(source + ": device index " + text + " is past any device's (devices are numbered from 0; "
                            "tfmatch devices lists them)");
  return uint32_t(index);
}

namespace {

constexpr const char* kValidationLayer = "VK_LAYER_KHRONOS_validation";

// The global commands below (vkEnumerateInstance*, vkCreateInstance) are volk's renamed globals,
// filled from the system loader by loader_get_instance_proc_addr(), which callers run first.
// Everything else goes through a Dispatch.

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

const char* device_type_name(VkPhysicalDeviceType type) {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return "discrete GPU";
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return "integrated GPU";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return "virtual GPU";
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return "CPU";
    default: return "other";
  }
}

bool layer_available(const char* name) {
  uint32_t count = 0;
  VK_CHECK(vkEnumerateInstanceLayerProperties(&count, nullptr));
  std::vector<VkLayerProperties> layers(count);
  VK_CHECK(vkEnumerateInstanceLayerProperties(&count, layers.data()));
  return std::any_of(layers.begin(), layers.end(),
                     [&](const VkLayerProperties& l) { return std::strcmp(l.layerName, name) == 0; });
}

bool instance_extension_available(const char* name) {
  uint32_t count = 0;
  VK_CHECK(vkEnumerateInstanceExtensionProperties(nullptr, &count, nullptr));
  std::vector<VkExtensionProperties> exts(count);
  VK_CHECK(vkEnumerateInstanceExtensionProperties(nullptr, &count, exts.data()));
  return std::any_of(exts.begin(), exts.end(), [&](const VkExtensionProperties& e) {
    return std::strcmp(e.extensionName, name) == 0;
  });
}

std::optional<uint32_t> compute_queue_family(const Dispatch& vk, VkPhysicalDevice pd, uint32_t* timestamp_bits) {
  uint32_t count = 0;
  vk.vkGetPhysicalDeviceQueueFamilyProperties(pd, &count, nullptr);
  std::vector<VkQueueFamilyProperties> families(count);
  vk.vkGetPhysicalDeviceQueueFamilyProperties(pd, &count, families.data());
  // Prefer a compute family with timestamps; any compute family otherwise.
  std::optional<uint32_t> best;
  for (uint32_t i = 0; i < count; ++i) {
    if (!(families[i].queueFlags & VK_QUEUE_COMPUTE_BIT)) continue;
    if (!best || (families[i].timestampValidBits > 0 && families[*best].timestampValidBits == 0))
      best = i;
  }
  if (best && timestamp_bits) *timestamp_bits = families[*best].timestampValidBits;
  return best;
}

VkInstance create_instance(bool validation, bool debug_utils) {
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "tfmatch";
  app.pEngineName = "tfmatch";
  app.apiVersion = VK_API_VERSION_1_2;

  std::vector<const char*> layers;
  std::vector<const char*> extensions;
  if (validation) layers.push_back(kValidationLayer);
  if (debug_utils) extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);

  // Synchronization validation checks that every barrier orders what it must.
  VkValidationFeatureEnableEXT enables[] = {VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT};
  VkValidationFeaturesEXT features{VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT};
  features.enabledValidationFeatureCount = 1;
  features.pEnabledValidationFeatures = enables;

  VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  info.pApplicationInfo = &app;
  info.enabledLayerCount = static_cast<uint32_t>(layers.size());
  info.ppEnabledLayerNames = layers.data();
  info.enabledExtensionCount = static_cast<uint32_t>(extensions.size());
  info.ppEnabledExtensionNames = extensions.data();
  if (validation) info.pNext = &features;
  VkInstance instance = VK_NULL_HANDLE;
  VK_CHECK(vkCreateInstance(&info, nullptr, &instance));
  return instance;
}

std::vector<VkPhysicalDevice> physical_devices(const Dispatch& vk, VkInstance instance) {
  uint32_t count = 0;
  VK_CHECK(vk.vkEnumeratePhysicalDevices(instance, &count, nullptr));
  std::vector<VkPhysicalDevice> devices(count);
  VK_CHECK(vk.vkEnumeratePhysicalDevices(instance, &count, devices.data()));
  return devices;
}

// Whether `pd` supports 64-bit integer atomics on buffers and shared memory (Vulkan 1.2 features).
bool device_extension_available(const Dispatch& vk, VkPhysicalDevice pd, const char* name) {
  uint32_t count = 0;
  VK_CHECK(vk.vkEnumerateDeviceExtensionProperties(pd, nullptr, &count, nullptr));
  std::vector<VkExtensionProperties> exts(count);
  VK_CHECK(vk.vkEnumerateDeviceExtensionProperties(pd, nullptr, &count, exts.data()));
  return std::any_of(exts.begin(), exts.end(),
                     [&](const VkExtensionProperties& e) { return std::strcmp(e.extensionName, name) == 0; });
}

bool supports_int64_atomics(const Dispatch& vk, VkPhysicalDevice pd) {
  VkPhysicalDeviceProperties props{};
  vk.vkGetPhysicalDeviceProperties(pd, &props);
  if (props.apiVersion < VK_API_VERSION_1_2 || !vk.vkGetPhysicalDeviceFeatures2) return false;
  VkPhysicalDeviceShaderAtomicInt64Features atomics{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_ATOMIC_INT64_FEATURES};
  VkPhysicalDeviceFeatures2 features{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
  features.pNext = &atomics;
  vk.vkGetPhysicalDeviceFeatures2(pd, &features);
  return features.features.shaderInt64 && atomics.shaderBufferInt64Atomics && atomics.shaderSharedInt64Atomics;
}

uint32_t compute_subgroup_operations(const VkPhysicalDeviceSubgroupProperties& p) {
  return (p.supportedStages & VK_SHADER_STAGE_COMPUTE_BIT) ? p.supportedOperations : 0u;
}

DeviceSummary summarize(const Dispatch& vk, VkPhysicalDevice pd, uint32_t index) {
  VkPhysicalDeviceSubgroupProperties subgroup{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES};
  VkPhysicalDeviceDriverProperties driver{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES};
  subgroup.pNext = &driver;
  VkPhysicalDeviceProperties2 props{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
  props.pNext = &subgroup;
  vk.vkGetPhysicalDeviceProperties2(pd, &props);
  VkPhysicalDeviceFeatures features{};
  vk.vkGetPhysicalDeviceFeatures(pd, &features);
  VkPhysicalDeviceMemoryProperties mem{};
  vk.vkGetPhysicalDeviceMemoryProperties(pd, &mem);

  DeviceSummary s;
  s.index = index;
  s.name = props.properties.deviceName;
  s.type = device_type_name(props.properties.deviceType);
  s.driver = std::string(driver.driverName) + " " + driver.driverInfo;
  s.api_version = props.properties.apiVersion;
  s.max_storage_buffer_range = props.properties.limits.maxStorageBufferRange;
  s.max_shared_memory_bytes = props.properties.limits.maxComputeSharedMemorySize;
  s.max_workgroup_invocations = props.properties.limits.maxComputeWorkGroupInvocations;
  s.subgroup_size = subgroup.subgroupSize;
  s.shader_float64 = features.shaderFloat64;
  s.int64_atomics = supports_int64_atomics(vk, pd);
  s.subgroup_operations = compute_subgroup_operations(subgroup);
  uint32_t ts_bits = 0;
  s.compute_queue = compute_queue_family(vk, pd, &ts_bits).has_value();
  s.timestamps = ts_bits > 0 && props.properties.limits.timestampPeriod > 0;
  for (uint32_t i = 0; i < mem.memoryHeapCount; ++i)
    if (mem.memoryHeaps[i].flags & VK_MEMORY_HEAP_DEVICE_LOCAL_BIT)
      s.device_local_bytes = std::max<uint64_t>(s.device_local_bytes, mem.memoryHeaps[i].size);
  return s;
}

// The options with what the environment says filled in (ContextOptions).
ContextOptions with_environment(ContextOptions options) {
  if (!options.device_index && options.device_name.empty()) {
    if (const char* env = std::getenv("TFMATCH_DEVICE"); env && *env) {
      if (std::optional<uint32_t> index = parse_device_index(env, "TFMATCH_DEVICE")) options.device_index = index;
      else options.device_name = env;
    }
  }
  if (!options.validation) {
    const char* env = std::getenv("TFMATCH_VALIDATION");
    options.validation = env && std::string(env) != "0" && *env;
  }
  return options;
}

// The index in `devices` that `options` select; throws DeviceChoiceError naming the devices
// when none fits.
uint32_t choose_device(const Dispatch& vk, const std::vector<VkPhysicalDevice>& devices, const ContextOptions& options) {
  std::vector<DeviceSummary> summaries;
  for (uint32_t i = 0; i < devices.size(); ++i) summaries.push_back(summarize(vk, devices[i], i));
  auto list = [&] {
    std::ostringstream os;
    for (auto& s : summaries) os << "\n  [" << s.index << "] " << s.name << " (" << s.type << ")";
    return os.str();
  };
  if (devices.empty())
    throw DeviceChoiceError("no Vulkan device found (install mesa-vulkan-drivers for lavapipe)");

  std::optional<uint32_t> chosen;
  if (options.device_index) {
    if (*options.device_index >= devices.size())
      throw DeviceChoiceError("device index " + std::to_string(*options.device_index) +
                               " out of range; devices:" + list());
    chosen = *options.device_index;
  } else if (!options.device_name.empty()) {
    for (auto& s : summaries)
      if (lower(s.name).find(lower(options.device_name)) != std::string::npos && s.compute_queue) {
        chosen = s.index;
        break;
      }
    if (!chosen)
      throw DeviceChoiceError("no device name contains '" + options.device_name + "'; devices:" + list());
  } else {
    // Default: a discrete GPU, then integrated, then anything with a compute queue.
    int best_rank = -1;
    for (auto& s : summaries) {
      if (!s.compute_queue) continue;
      int rank = s.type == "discrete GPU" ? 3 : s.type == "integrated GPU" ? 2 : s.type == "CPU" ? 0 : 1;
      if (rank > best_rank) best_rank = rank, chosen = s.index;
    }
    if (!chosen) throw DeviceChoiceError("no Vulkan device has a compute queue; devices:" + list());
  }
  if (!summaries[*chosen].compute_queue)
    throw DeviceChoiceError("device " + summaries[*chosen].name + " has no compute queue");
  return *chosen;
}

// A device of `pd` with one queue of `family`, and what `info` (features, extensions, pNext)
// enables beside it: Context::create's device, and the driver floor's bare one.
VkDevice create_device(const Dispatch& vk, VkPhysicalDevice pd, uint32_t family, VkDeviceCreateInfo info) {
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queue_info.queueFamilyIndex = family;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  info.queueCreateInfoCount = 1;
  info.pQueueCreateInfos = &queue_info;
  VkDevice device = VK_NULL_HANDLE;
  VK_CHECK(vk.vkCreateDevice(pd, &info, nullptr, &device));
  return device;
}

}  // namespace

std::vector<DeviceSummary> enumerate_devices() {
  PFN_vkGetInstanceProcAddr get = loader_get_instance_proc_addr();
  VkInstance instance = create_instance(false, false);
  Dispatch vk{};
  load_instance_functions(vk, get, instance);
  std::vector<DeviceSummary> out;
  auto devices = physical_devices(vk, instance);
  for (uint32_t i = 0; i < devices.size(); ++i) out.push_back(summarize(vk, devices[i], i));
  vk.vkDestroyInstance(instance, nullptr);
  return out;
}

DriverFloor measure_driver_floor(const ContextOptions& options_in) {
  using clock = std::chrono::steady_clock;
  auto ms = [](clock::time_point a, clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  const ContextOptions options = with_environment(options_in);
  PFN_vkGetInstanceProcAddr get = loader_get_instance_proc_addr();
  // Which device: chosen on an instance of its own, as Context::create chooses, so the timed
  // instance below does nothing but what the minimal program does.
  uint32_t chosen = 0;
  DriverFloor floor;
  {
    VkInstance probe = create_instance(false, false);
    Dispatch vk{};
    load_instance_functions(vk, get, probe);
    try {
      const auto devices = physical_devices(vk, probe);
      chosen = choose_device(vk, devices, options);
      floor.device = summarize(vk, devices[chosen], chosen).name;
    } catch (...) {
      vk.vkDestroyInstance(probe, nullptr);
      throw;
    }
    vk.vkDestroyInstance(probe, nullptr);
  }

  const auto t0 = clock::now();
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.apiVersion = VK_API_VERSION_1_2;
  VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  info.pApplicationInfo = &app;
  VkInstance instance = VK_NULL_HANDLE;
  VK_CHECK(vkCreateInstance(&info, nullptr, &instance));
  const auto t1 = clock::now();
  Dispatch vk{};
  load_instance_functions(vk, get, instance);
  VkDevice device = VK_NULL_HANDLE;
  try {
    const auto devices = physical_devices(vk, instance);
    const uint32_t family = *compute_queue_family(vk, devices.at(chosen), nullptr);
    device = create_device(vk, devices[chosen], family, {VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO});
  } catch (...) {
    vk.vkDestroyInstance(instance, nullptr);
    throw;
  }
  const auto t2 = clock::now();
  auto destroy_device = reinterpret_cast<PFN_vkDestroyDevice>(vk.vkGetDeviceProcAddr(device, "vkDestroyDevice"));
  destroy_device(device, nullptr);
  vk.vkDestroyInstance(instance, nullptr);
  const auto t3 = clock::now();
  floor.instance_ms = ms(t0, t1);
  floor.device_ms = ms(t1, t2);
  floor.teardown_ms = ms(t2, t3);
  return floor;
}

Context::Context()
    : dispatch_(std::make_unique<Dispatch>()),
      staging_(std::make_unique<StagingBuffers>()),
      pipelines_(std::make_unique<PipelineRegistry>(*this)) {}

std::unique_ptr<Context> Context::create(const ContextOptions& options_in) {
  PhaseScope timing(Phase::Startup);
  PFN_vkGetInstanceProcAddr get = loader_get_instance_proc_addr();
  const ContextOptions options = with_environment(options_in);

  std::unique_ptr<Context> ctx(new Context());
  ctx->owns_ = true;
  bool want_validation = *options.validation;
  if (want_validation && !layer_available(kValidationLayer)) {
    if (options.require_validation)
      throw std::runtime_error(std::string(kValidationLayer) +
                               " requested but not installed (apt-get install vulkan-validationlayers)");
    want_validation = false;
  }
  ctx->validation_ = want_validation;
  ctx->debug_utils_ = instance_extension_available(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  ctx->instance_ = create_instance(want_validation, ctx->debug_utils_);
  Dispatch& vk = *ctx->dispatch_;
  load_instance_functions(vk, get, ctx->instance_);

  if (ctx->debug_utils_ && want_validation) {
    VkDebugUtilsMessengerCreateInfoEXT info{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
    info.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                           VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT;
    info.pfnUserCallback = &Context::debug_callback;
    info.pUserData = ctx.get();
    VK_CHECK(vk.vkCreateDebugUtilsMessengerEXT(ctx->instance_, &info, nullptr, &ctx->messenger_));
  }

  auto devices = physical_devices(vk, ctx->instance_);
  const uint32_t chosen = choose_device(vk, devices, options);
  ctx->physical_device_ = devices[chosen];
  ctx->queue_family_ = *compute_queue_family(vk, ctx->physical_device_, nullptr);

  VkPhysicalDeviceFeatures supported{};
  vk.vkGetPhysicalDeviceFeatures(ctx->physical_device_, &supported);
  VkPhysicalDeviceFeatures enabled{};
  // Arrays of field chunks are indexed per sample by the renderer.
  enabled.shaderStorageBufferArrayDynamicIndexing = supported.shaderStorageBufferArrayDynamicIndexing;
  // 64-bit atomics halve the atomics of the accumulating kernels (one per fixed-point slot).
  // Enabled through the atomic-int64 struct rather than VkPhysicalDeviceVulkan12Features: with
  // the latter, a host's own validated instance in the same process crashed when it destroyed
  // its debug messenger (test EmbeddingVolk).
  VkPhysicalDeviceShaderAtomicInt64Features atomic_features{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_ATOMIC_INT64_FEATURES};
  const bool int64_atomics = supports_int64_atomics(vk, ctx->physical_device_);
  if (int64_atomics) {
    enabled.shaderInt64 = VK_TRUE;
    atomic_features.shaderBufferInt64Atomics = VK_TRUE;
    atomic_features.shaderSharedInt64Atomics = VK_TRUE;
  }
  // Importing host memory lets large transfers skip the staging copy (buffer.cpp).
  const bool external_memory_host =
      device_extension_available(vk, ctx->physical_device_, VK_EXT_EXTERNAL_MEMORY_HOST_EXTENSION_NAME);
  std::vector<const char*> device_extensions;
  if (external_memory_host) device_extensions.push_back(VK_EXT_EXTERNAL_MEMORY_HOST_EXTENSION_NAME);
  VkDeviceCreateInfo device_info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  if (int64_atomics) device_info.pNext = &atomic_features;
  device_info.enabledExtensionCount = static_cast<uint32_t>(device_extensions.size());
  device_info.ppEnabledExtensionNames = device_extensions.data();
  device_info.pEnabledFeatures = &enabled;
  ctx->device_ = create_device(vk, ctx->physical_device_, ctx->queue_family_, device_info);
  load_device_functions(vk, ctx->device_);
  vk.vkGetDeviceQueue(ctx->device_, ctx->queue_family_, 0, &ctx->queue_);
  ctx->int64_atomics_ = int64_atomics;
  ctx->load_device_info(external_memory_host);
  ctx->create_pipeline_cache(VK_NULL_HANDLE);
  return ctx;
}

std::unique_ptr<Context> Context::adopt(const ExternalDevice& external) {
  if (!external.instance || !external.physical_device || !external.device || !external.queue)
    throw std::invalid_argument("Context::adopt: instance, physical device, device and queue are required");
  if (external.api_version < VK_API_VERSION_1_2)
    throw std::invalid_argument(
        "Context::adopt: ExternalDevice::api_version is " +
        (external.api_version ? std::to_string(VK_API_VERSION_MAJOR(external.api_version)) + "." +
                                    std::to_string(VK_API_VERSION_MINOR(external.api_version))
                              : std::string("not given")) +
        ": give the VkApplicationInfo::apiVersion the instance was created with, VK_API_VERSION_1_2 or later "
        "(tfmatch's shaders need Vulkan 1.2)");
  PFN_vkGetInstanceProcAddr get =
      external.get_instance_proc_addr ? external.get_instance_proc_addr : loader_get_instance_proc_addr();
  std::unique_ptr<Context> ctx(new Context());
  ctx->owns_ = false;
  ctx->instance_ = external.instance;
  ctx->physical_device_ = external.physical_device;
  ctx->device_ = external.device;
  ctx->queue_ = external.queue;
  ctx->queue_family_ = external.queue_family_index;
  Dispatch& vk = *ctx->dispatch_;
  load_instance_functions(vk, get, external.instance);
  load_device_functions(vk, external.device);
  // Debug names work only if the host enabled VK_EXT_debug_utils; the entry point says so.
  ctx->debug_utils_ = vk.vkSetDebugUtilsObjectNameEXT != nullptr;
  VkPhysicalDeviceProperties device_properties{};
  vk.vkGetPhysicalDeviceProperties(external.physical_device, &device_properties);
  if (device_properties.apiVersion < VK_API_VERSION_1_2)
    throw std::invalid_argument(
        "Context::adopt: the device (" + std::string(device_properties.deviceName) + ") supports Vulkan " +
        std::to_string(VK_API_VERSION_MAJOR(device_properties.apiVersion)) + "." +
        std::to_string(VK_API_VERSION_MINOR(device_properties.apiVersion)) + "; tfmatch needs 1.2");
  ctx->int64_atomics_ = external.int64_atomics_enabled && supports_int64_atomics(vk, external.physical_device);
  ctx->load_device_info(external.external_memory_host_enabled);
  ctx->create_pipeline_cache(external.pipeline_cache);
  return ctx;
}

void Context::load_device_info(bool external_memory_host) {
  const Dispatch& vk = *dispatch_;
  vk.vkGetPhysicalDeviceProperties(physical_device_, &properties_);
  vk.vkGetPhysicalDeviceMemoryProperties(physical_device_, &memory_);
  uint32_t count = 0;
  vk.vkGetPhysicalDeviceQueueFamilyProperties(physical_device_, &count, nullptr);
  std::vector<VkQueueFamilyProperties> families(count);
  vk.vkGetPhysicalDeviceQueueFamilyProperties(physical_device_, &count, families.data());
  if (queue_family_ >= count) throw std::invalid_argument("queue family index out of range");
  if (!(families[queue_family_].queueFlags & VK_QUEUE_COMPUTE_BIT))
    throw std::invalid_argument("the queue family given to tfmatch has no compute capability");
  timestamp_valid_bits_ = properties_.limits.timestampPeriod > 0 ? families[queue_family_].timestampValidBits : 0;

  VkPhysicalDeviceExternalMemoryHostPropertiesEXT host_memory{
      VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_EXTERNAL_MEMORY_HOST_PROPERTIES_EXT};
  VkPhysicalDeviceMaintenance3Properties maint3{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MAINTENANCE_3_PROPERTIES};
  if (external_memory_host) maint3.pNext = &host_memory;
  VkPhysicalDeviceSubgroupProperties subgroup{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES};
  subgroup.pNext = &maint3;
  VkPhysicalDeviceDriverProperties driver{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES};
  driver.pNext = &subgroup;
  VkPhysicalDeviceProperties2 props2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
  props2.pNext = &driver;
  vk.vkGetPhysicalDeviceProperties2(physical_device_, &props2);
  // Mesa's llvmpipe counts every loop iteration of a shader invocation against one limit of
  // 65535 (LP_MAX_TGSI_LOOP_ITERATIONS, "shared between every loop") and then ends every loop.
  loop_iteration_limit_ = driver.driverID == VK_DRIVER_ID_MESA_LLVMPIPE ? 65535u : 0u;
  driver_description_ = std::string(driver.driverName) + " " + driver.driverInfo + ", Vulkan " +
                        std::to_string(VK_API_VERSION_MAJOR(properties_.apiVersion)) + "." +
                        std::to_string(VK_API_VERSION_MINOR(properties_.apiVersion)) + "." +
                        std::to_string(VK_API_VERSION_PATCH(properties_.apiVersion));
  subgroup_size_ = subgroup.subgroupSize;
  subgroup_operations_ = compute_subgroup_operations(subgroup);
  max_allocation_bytes_ = maint3.maxMemoryAllocationSize;
  if (external_memory_host && dispatch_->vkGetMemoryHostPointerPropertiesEXT)
    min_import_alignment_ = host_memory.minImportedHostPointerAlignment;
  const char* env = std::getenv("TFMATCH_HOST_IMPORT");
  set_host_import(!(env && std::string(env) == "0"));
}

void Context::create_pipeline_cache(VkPipelineCache borrowed) {
  if (borrowed) {
    pipeline_cache_ = borrowed;
    return;
  }
  VkPipelineCacheCreateInfo info{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
  VK_CHECK(dispatch_->vkCreatePipelineCache(device_, &info, nullptr, &pipeline_cache_));
  owns_pipeline_cache_ = true;
}

VkFormatFeatureFlags Context::buffer_format_features(VkFormat format) const {
  std::lock_guard lock(format_features_mutex_);
  for (const auto& [known, features] : buffer_format_features_)
    if (known == format) return features;
  VkFormatProperties props{};
  dispatch_->vkGetPhysicalDeviceFormatProperties(physical_device_, format, &props);
  buffer_format_features_.emplace_back(format, props.bufferFeatures);
  return props.bufferFeatures;
}

std::string Context::pipeline_cache_identity() const {
  char head[64];
  std::snprintf(head, sizeof head, "%04x-%04x-%08x-", properties_.vendorID, properties_.deviceID,
                properties_.driverVersion);
  std::string id = head;
  for (uint8_t byte : properties_.pipelineCacheUUID) {
    char hex[3];
    std::snprintf(hex, sizeof hex, "%02x", byte);
    id += hex;
  }
  return id;
}

bool Context::merge_pipeline_cache_data(std::span<const uint8_t> data, std::string* why_not) {
  // The header every implementation writes first (VkPipelineCacheHeaderVersionOne): length,
  // version, vendor ID, device ID, pipelineCacheUUID. Checked here so that data of another
  // device or driver build is never handed to a driver, some of which trust what they are given.
  auto refuse = [&](const std::string& why) {
    if (why_not) *why_not = why;
    return false;
  };
  auto word = [&](size_t i) {
    uint32_t w = 0;
    std::memcpy(&w, data.data() + 4 * i, 4);
    return w;
  };
  constexpr size_t kHeaderBytes = 16 + VK_UUID_SIZE;
  if (data.size() < kHeaderBytes) return refuse("shorter than a pipeline-cache header");
  if (word(0) < kHeaderBytes || word(0) > data.size()) return refuse("header length " + std::to_string(word(0)) + " is not valid");
  if (word(1) != VK_PIPELINE_CACHE_HEADER_VERSION_ONE) return refuse("header version " + std::to_string(word(1)) + " is not 1");
  if (word(2) != properties_.vendorID || word(3) != properties_.deviceID) return refuse("written for another device");
  if (std::memcmp(data.data() + 16, properties_.pipelineCacheUUID, VK_UUID_SIZE) != 0)
    return refuse("written by another driver build (pipelineCacheUUID differs)");
  VkPipelineCacheCreateInfo info{VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO};
  info.initialDataSize = data.size();
  info.pInitialData = data.data();
  VkPipelineCache loaded = VK_NULL_HANDLE;
  VK_CHECK(dispatch_->vkCreatePipelineCache(device_, &info, nullptr, &loaded));
  std::unique_lock lock(pipeline_cache_mutex_);
  const VkResult merged = dispatch_->vkMergePipelineCaches(device_, pipeline_cache_, 1, &loaded);
  dispatch_->vkDestroyPipelineCache(device_, loaded, nullptr);
  VK_CHECK(merged);
  return true;
}

std::vector<uint8_t> Context::pipeline_cache_data() {
  std::shared_lock lock(pipeline_cache_mutex_);
  // The size can grow between the two calls only if a pipeline is created meanwhile on another
  // thread: VK_INCOMPLETE then asks for another round.
  for (;;) {
    size_t size = 0;
    VK_CHECK(dispatch_->vkGetPipelineCacheData(device_, pipeline_cache_, &size, nullptr));
    std::vector<uint8_t> data(size);
    const VkResult r = dispatch_->vkGetPipelineCacheData(device_, pipeline_cache_, &size, data.data());
    if (r == VK_INCOMPLETE) continue;
    VK_CHECK(r);
    data.resize(size);
    return data;
  }
}

PFN_vkGetDeviceProcAddr Context::get_device_proc_addr() const { return dispatch_->vkGetDeviceProcAddr; }

uint64_t Context::max_buffer_bytes() const {
  uint64_t limit = properties_.limits.maxStorageBufferRange;
  if (max_allocation_bytes_ > 0) limit = std::min(limit, max_allocation_bytes_);
  return limit;
}

Context::~Context() {
  pipelines_.reset();  // pipelines and staging buffers belong to the device, also an adopted one
  staging_.reset();
  if (const int64_t live = live_buffer_memory_.load(); live != 0) {
    // A use after free follows (the buffers free their memory on the destroyed device): stop
    // here, saying why, rather than crash later somewhere unrelated.
    std::fprintf(stderr,
                 "tfmatch: a Context is destroyed while %lld buffers made on it (fields, recorders, solvers' "
                 "accumulators) still exist; destroy every tfmatch object made on a Context before the Context "
                 "(docs/embedding.md, \"Ownership\")\n",
                 static_cast<long long>(live));
    std::abort();
  }
  const Dispatch& vk = *dispatch_;
  if (owns_pipeline_cache_) vk.vkDestroyPipelineCache(device_, pipeline_cache_, nullptr);
  if (!owns_) return;
  if (device_) {
    vk.vkDeviceWaitIdle(device_);
    vk.vkDestroyDevice(device_, nullptr);
  }
  if (messenger_) vk.vkDestroyDebugUtilsMessengerEXT(instance_, messenger_, nullptr);
  if (instance_ && vk.vkDestroyInstance) vk.vkDestroyInstance(instance_, nullptr);
}

std::vector<std::string> Context::take_validation_messages() {
  std::lock_guard lock(messages_mutex_);
  return std::exchange(messages_, {});
}

void Context::set_debug_name(VkObjectType type, uint64_t handle, const char* name) const {
  if (!debug_utils_ || !dispatch_->vkSetDebugUtilsObjectNameEXT || !name) return;
  VkDebugUtilsObjectNameInfoEXT info{VK_STRUCTURE_TYPE_DEBUG_UTILS_OBJECT_NAME_INFO_EXT};
  info.objectType = type;
  info.objectHandle = handle;
  info.pObjectName = name;
  dispatch_->vkSetDebugUtilsObjectNameEXT(device_, &info);
}

VKAPI_ATTR VkBool32 VKAPI_CALL Context::debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                       VkDebugUtilsMessageTypeFlagsEXT,
                                                       const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                       void* user) {
  auto* ctx = static_cast<Context*>(user);
  std::string text = (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) ? "error: " : "warning: ";
  text += data && data->pMessage ? data->pMessage : "(no message)";
  std::lock_guard lock(ctx->messages_mutex_);
  ctx->messages_.push_back(std::move(text));
  return VK_FALSE;
}

}  // namespace tfm
