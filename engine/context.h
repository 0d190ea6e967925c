// The Vulkan device tfmatch computes on: created and owned here, or adopted from a host application.
// Like every engine header it needs Vulkan's types only, so it works in a host that uses the
// loader's prototypes (<vulkan/vulkan.h>, before or after) and in one that uses its own volk
// (which, as volk asks, defines VK_NO_PROTOTYPES or includes volk.h first).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <span>
#include <string>
#include <stdexcept>
#include <utility>
#include <vector>

#include <vulkan/vulkan_core.h>

#include "tfmatch/engine/buffer.h"

namespace tfm {

struct Dispatch;  // engine/vk_dispatch.h, private to engine/*.cpp
class PipelineRegistry;  // pipeline.h

// How to choose and create a device. Environment variables fill what is left unset:
// TFMATCH_DEVICE (index or name substring), TFMATCH_VALIDATION=1.
struct ContextOptions {
  std::optional<uint32_t> device_index;
  std::string device_name;          // case-insensitive substring of the device name
  std::optional<bool> validation;   // Khronos validation layer (+ synchronization validation)
  bool require_validation = false;  // throw when the layer is requested but not installed
};

// No device is as the options ask: none at all, an index past the devices, a name no device
// contains, or none with a compute queue. The message lists the devices there are.
class DeviceChoiceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The device index `text` spells (digits only), nullopt when it is a name. Throws
// DeviceChoiceError, saying `source` (an option or variable), for an index past 2^32 - 1:
// taken modulo 2^32 it chose another device.
std::optional<uint32_t> parse_device_index(const std::string& text, const std::string& source);

// Handles of a host application's Vulkan objects. The context borrows them and never destroys
// them; the host must keep them alive and must not use `queue` concurrently with tfmatch
// (Vulkan requires external synchronization of a queue).
struct ExternalDevice {
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t queue_family_index = 0;
  // The host's vkGetInstanceProcAddr, through which tfmatch then resolves every command it calls
  // on these handles; null means the system Vulkan loader's.
  PFN_vkGetInstanceProcAddr get_instance_proc_addr = nullptr;
  // Set when the host created `device` with shaderInt64, shaderBufferInt64Atomics and
  // shaderSharedInt64Atomics enabled: the accumulating kernels then use 64-bit atomics.
  bool int64_atomics_enabled = false;
  // The host's pipeline cache for tfmatch's pipelines (borrowed, never destroyed); null: tfmatch
  // keeps one of its own for the context's lifetime.
  VkPipelineCache pipeline_cache = VK_NULL_HANDLE;
  // Set when the host enabled VK_EXT_external_memory_host on `device`: large transfers then copy
  // straight from and to the caller's host memory (buffer.h).
  bool external_memory_host_enabled = false;
  // The VkApplicationInfo::apiVersion the host created `instance` with. Required, at least
  // VK_API_VERSION_1_2: tfmatch's shaders are SPIR-V for Vulkan 1.2 (subgroup operations) and it
  // calls 1.1 commands. Vulkan cannot tell an instance's version from its handle, and an instance
  // made without VkApplicationInfo is 1.0, where every pipeline is invalid (undefined behaviour
  // without the validation layer), so adopt() refuses 0 and anything below 1.2.
  uint32_t api_version = 0;
};

struct DeviceSummary {
  uint32_t index = 0;
  std::string name;
  std::string type;                // "discrete GPU", "CPU", ...
  std::string driver;              // driver name and info
  uint32_t api_version = 0;
  uint64_t max_storage_buffer_range = 0;
  uint32_t max_shared_memory_bytes = 0;
  uint32_t max_workgroup_invocations = 0;
  uint32_t subgroup_size = 0;
  bool timestamps = false;
  bool shader_float64 = false;
  bool int64_atomics = false;        // shaderInt64 with 64-bit buffer and shared atomics
  uint32_t subgroup_operations = 0;  // VkSubgroupFeatureFlags of compute shaders
  bool compute_queue = false;
  uint64_t device_local_bytes = 0;
};

// Lists every physical device the loader reports (creates a temporary instance).
std::vector<DeviceSummary> enumerate_devices();

// What the driver alone costs a process, the floor under any Vulkan program's start-up: a bare
// instance (no layers, no extensions), the device Context::create would choose created with one
// compute queue and nothing enabled, and both destroyed, each timed (the choice itself is made on
// an instance of its own, untimed). Throws as Context::create does when no device fits.
struct DriverFloor {
  std::string device;
  double instance_ms = 0.0, device_ms = 0.0, teardown_ms = 0.0;
  double total_ms() const { return instance_ms + device_ms + teardown_ms; }
};
DriverFloor measure_driver_floor(const ContextOptions& options = {});

class Context {
 public:
  // Creates instance, device and compute queue. Throws std::runtime_error when no suitable
  // device exists or the selection matches none (the message lists the devices).
  static std::unique_ptr<Context> create(const ContextOptions& options = {});
  // Wraps a host application's objects without taking ownership (never touching a host's volk);
  // throws VulkanError if the loader cannot be initialized or resolves no vkGetDeviceProcAddr.
  static std::unique_ptr<Context> adopt(const ExternalDevice& external);

  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  VkInstance instance() const { return instance_; }
  VkPhysicalDevice physical_device() const { return physical_device_; }
  VkDevice device() const { return device_; }
  VkQueue queue() const { return queue_; }
  uint32_t queue_family() const { return queue_family_; }
  bool owns_device() const { return owns_; }
  // This device's vkGetDeviceProcAddr, for a host that records its own commands on it.
  PFN_vkGetDeviceProcAddr get_device_proc_addr() const;
  // The entry points tfmatch calls for this context; the type is known to engine/*.cpp only.
  const Dispatch& vk() const { return *dispatch_; }

  const VkPhysicalDeviceProperties& properties() const { return properties_; }
  const VkPhysicalDeviceLimits& limits() const { return properties_.limits; }
  const VkPhysicalDeviceMemoryProperties& memory_properties() const { return memory_; }
  std::string device_name() const { return properties_.deviceName; }
  // What the device can do with `format` in a buffer (VkFormatProperties::bufferFeatures), e.g.
  // VK_FORMAT_FEATURE_UNIFORM_TEXEL_BUFFER_BIT, which the kernels need of every field format they
  // read as texels: Vulkan makes it mandatory for R32_SFLOAT, R16_SFLOAT and R8_UNORM (and their
  // RGBA forms) but not for R16_UNORM, which a device may lack. Asked of the driver once per format
  // (every dispatch that binds texels asks).
  VkFormatFeatureFlags buffer_format_features(VkFormat format) const;
  // The driver and the Vulkan version it reports, as `tfmatch devices` shows them: "llvmpipe Mesa
  // 22.3.6, Vulkan 1.3.230" (figures and reports name the driver beside the device).
  const std::string& driver_description() const { return driver_description_; }
  bool timestamps_supported() const { return timestamp_valid_bits_ > 0; }
  uint32_t subgroup_size() const { return subgroup_size_; }
  // VkSubgroupFeatureFlags supported in compute shaders (0 when compute has no subgroup ops).
  uint32_t subgroup_operations() const { return subgroup_operations_; }
  // Loop iterations one shader invocation may run in all before the driver ends its loops
  // silently: 65535 on llvmpipe (lavapipe); 0 where no such limit is known. Kernels whose loops
  // grow with their inputs (ray marching) check their worst case against it.
  uint32_t loop_iteration_limit() const { return loop_iteration_limit_; }
  // Whether shaders may use 64-bit integers with atomics on buffer and shared memory: enabled by
  // Context::create where the device supports them, declared by the host for an adopted device.
  bool int64_atomics() const { return int64_atomics_; }
  // Largest buffer a single storage-buffer descriptor may address (and one allocation may hold).
  uint64_t max_buffer_bytes() const;
  // Whether large transfers import the caller's host memory (VK_EXT_external_memory_host: the
  // copy engine reads or writes it in place, no staging copy): enabled where the device has the
  // extension, unless TFMATCH_HOST_IMPORT=0; set_host_import(false) turns it off for this context.
  bool host_import() const { return host_import_; }
  void set_host_import(bool enabled) { host_import_ = enabled && min_import_alignment_ > 0; }
  // minImportedHostPointerAlignment: imported ranges start and end on multiples of it (0: none).
  uint64_t min_import_alignment() const { return min_import_alignment_; }

  // Validation messages (errors and warnings) seen since the last call; empty when validation
  // is off. Tests fail on any.
  bool validation_enabled() const { return validation_; }
  std::vector<std::string> take_validation_messages();

  // Serializes queue submissions made through this context.
  std::mutex& queue_mutex() { return queue_mutex_; }
  // The staging memory upload() reuses (buffer.h).
  StagingBuffers& staging() { return *staging_; }
  // The compute pipelines the kernels of this context share (pipeline.h).
  PipelineRegistry& pipelines() { return *pipelines_; }

  void set_debug_name(VkObjectType type, uint64_t handle, const char* name) const;

  // The pipeline cache every ComputePipeline of this context is created through. Pipelines are
  // created when a kernel first needs them; a cache filled by an earlier process (seeded with
  // merge_pipeline_cache_data) lets the driver skip compiling them again.
  VkPipelineCache pipeline_cache() const { return pipeline_cache_; }
  // Held shared while a pipeline is created through the cache, exclusively while data is merged
  // into it (Vulkan requires external synchronization of a merge's destination).
  std::shared_mutex& pipeline_cache_mutex() { return pipeline_cache_mutex_; }
  // What identifies the driver build a pipeline cache is valid for: vendor and device IDs, driver
  // version and the device's pipelineCacheUUID, as "vvvv-dddd-driver-uuidhex".
  std::string pipeline_cache_identity() const;
  // Adds the pipelines in `data` (vkGetPipelineCacheData's output of an earlier run) to this
  // context's cache. Data whose header names another device, driver build or header version is
  // not given to the driver: returns false and says why in `why_not` (a stale cache is harmless,
  // never an error). Throws VulkanError only when the driver fails on data that matched.
  bool merge_pipeline_cache_data(std::span<const uint8_t> data, std::string* why_not = nullptr);
  // The cache's contents now (vkGetPipelineCacheData), to store for the next run.
  std::vector<uint8_t> pipeline_cache_data();

  // Bytes held by tfm::Buffer objects of this context (device and staging), and the most held
  // at once since the last reset_peak_buffer_bytes(): benchmarks report peak memory with it.
  uint64_t buffer_bytes() const { return buffer_bytes_.load(); }
  uint64_t peak_buffer_bytes() const { return peak_buffer_bytes_.load(); }
  void reset_peak_buffer_bytes() { peak_buffer_bytes_.store(buffer_bytes_.load()); }
  // Queue submissions this context has made (CommandBatch::submit): none happen on the recording
  // path, where the host submits (tests check that the count does not move there).
  uint64_t submissions() const { return submissions_.load(); }
  void count_submission() { submissions_.fetch_add(1); }
  // Device memory allocations of tfm::Buffer objects on this context that are not yet freed
  // (called by Buffer): ~Context() stops the program with a message while any remain, since
  // freeing them afterwards would use the destroyed device.
  void track_buffer_memory(int delta) { live_buffer_memory_.fetch_add(delta); }
  void track_buffer_bytes(int64_t delta) {  // called by Buffer on allocation and release
    const uint64_t now = buffer_bytes_.fetch_add(uint64_t(delta)) + uint64_t(delta);
    uint64_t peak = peak_buffer_bytes_.load();
    while (now > peak && !peak_buffer_bytes_.compare_exchange_weak(peak, now)) {
    }
  }

 private:
  Context();
  void load_device_info(bool external_memory_host);
  void create_pipeline_cache(VkPipelineCache borrowed);
  static VKAPI_ATTR VkBool32 VKAPI_CALL debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                      VkDebugUtilsMessageTypeFlagsEXT,
                                                      const VkDebugUtilsMessengerCallbackDataEXT*,
                                                      void*);

  VkInstance instance_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  uint32_t queue_family_ = 0;
  bool owns_ = false;
  bool validation_ = false;
  bool debug_utils_ = false;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  std::unique_ptr<Dispatch> dispatch_;
  VkPhysicalDeviceProperties properties_{};
  VkPhysicalDeviceMemoryProperties memory_{};
  uint32_t timestamp_valid_bits_ = 0;
  uint32_t subgroup_size_ = 0;
  std::string driver_description_;
  uint32_t subgroup_operations_ = 0;
  uint32_t loop_iteration_limit_ = 0;
  bool int64_atomics_ = false;
  bool host_import_ = false;
  mutable std::mutex format_features_mutex_;
  mutable std::vector<std::pair<VkFormat, VkFormatFeatureFlags>> buffer_format_features_;  // asked so far
  uint64_t min_import_alignment_ = 0;
  uint64_t max_allocation_bytes_ = 0;
  std::mutex messages_mutex_;
  std::vector<std::string> messages_;
  std::mutex queue_mutex_;
  std::atomic<uint64_t> submissions_{0};
  std::atomic<uint64_t> buffer_bytes_{0}, peak_buffer_bytes_{0};
  std::atomic<int64_t> live_buffer_memory_{0};
  std::unique_ptr<StagingBuffers> staging_;  // released before the device
  std::unique_ptr<PipelineRegistry> pipelines_;  // likewise
  VkPipelineCache pipeline_cache_ = VK_NULL_HANDLE;
  bool owns_pipeline_cache_ = false;
  std::shared_mutex pipeline_cache_mutex_;
};

}  // namespace tfm
