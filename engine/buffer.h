// Device buffers (one allocation each, move-only) and staging transfers between host and device.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <span>
#include <string>

#include <vulkan/vulkan_core.h>

namespace tfm {

class Context;

enum class MemoryUsage {
  Device,    // device-local storage
  Upload,    // host-visible, host-coherent: written by the host
  Readback,  // host-visible, host-coherent, cached when the device offers it: read by the host
};

class Buffer {
 public:
  Buffer() = default;
  // Throws VulkanError (e.g. VK_ERROR_OUT_OF_DEVICE_MEMORY) and std::runtime_error when no
  // memory type fits. Usage always includes storage and transfer src/dst.
  Buffer(Context& ctx, uint64_t bytes, MemoryUsage usage, const std::string& debug_name);
  // A transfer buffer over `bytes` of the caller's host memory at `pointer` (both multiples of
  // Context::min_import_alignment()), imported with VK_EXT_external_memory_host: the device copies
  // from or to it in place. The memory must stay allocated, and the host must not touch it while
  // the device uses it. Returns an empty Buffer when the device cannot import that memory (no
  // extension, a read-only mapping, no host-coherent type for it). Not counted in buffer_bytes():
  // it allocates nothing. `kernels_read`: kernels may also bind it as a storage or uniform texel
  // buffer, to read the host memory in place (DeviceField::in_host_memory).
  static Buffer import_host(Context& ctx, void* pointer, uint64_t bytes, const std::string& debug_name,
                            bool kernels_read = false);
  // A view of `bytes` of a caller's device buffer from `offset` (an embedder's volume or TF
  // already on the device): kernels bind that range and copies address it, nothing is allocated,
  // and destroying the view leaves the caller's buffer alone. The buffer needs the usages the
  // kernels read it with (storage and uniform texel buffer for fields; transfer dst for a TF
  // written by record_tf_upload). Throws std::invalid_argument for a null buffer, no bytes, an
  // offset that is not a multiple of the device's storage- and texel-buffer offset alignments, or
  // a range past the buffer's memory requirement (at least its size: the check catches a range
  // past the end by more than the driver's rounding, not every one; the validation layer does).
  static Buffer adopt(Context& ctx, VkBuffer buffer, uint64_t offset, uint64_t bytes, const std::string& what);
  ~Buffer();
  Buffer(Buffer&& other) noexcept;
  Buffer& operator=(Buffer&& other) noexcept;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;

  VkBuffer handle() const { return buffer_; }
  // Where this buffer's bytes start in handle(): 0 except for an adopted range.
  uint64_t offset() const { return offset_; }
  bool adopted() const { return !owned_; }
  uint64_t size() const { return bytes_; }
  bool host_visible() const { return mapped_ != nullptr; }
  // Mapped pointer of an Upload/Readback buffer; null for Device buffers.
  void* mapped() const { return mapped_; }
  explicit operator bool() const { return buffer_ != VK_NULL_HANDLE; }

 private:
  void release();
  Context* ctx_ = nullptr;
  VkBuffer buffer_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  uint64_t offset_ = 0;
  uint64_t bytes_ = 0;
  void* mapped_ = nullptr;
  bool tracked_ = true;  // counted in the context's buffer_bytes()
  bool owned_ = true;    // false for an adopted range: the caller's buffer, not destroyed here
};

// Host memory upload() stages through, at most, and readback() at a time: bounded so that moving
// a large field never doubles its footprint.
inline constexpr uint64_t kStagingBytes = 64ull << 20;

// The staging memory upload() reuses, one per Context: two host-visible halves of at most 32 MiB,
// so the host fills one while the device copies the other. Kept between uploads because a new
// allocation is new memory the system must map and zero page by page (lavapipe: a streamed slab
// of 2 x 16.6 M voxels uploaded in 55-63 ms with new staging each time, 14-20 ms with these).
struct StagingBuffers {
  std::mutex mutex;  // held for a whole upload
  Buffer half[2];
};

// Host memory transfers at least this large copy their page-aligned interior straight from or to
// the caller's memory where the context imports host memory (Context::host_import()); the
// unaligned ends, and smaller transfers, go through staging.
inline constexpr uint64_t kHostImportMinBytes = 4ull << 20;

// Copies host bytes into `dst` at `offset`: in place where host memory can be imported, else
// through the context's staging buffers (a host buffer is written directly).
void upload(Context& ctx, Buffer& dst, const void* data, uint64_t bytes, uint64_t offset = 0);
// Copies `bytes` from `src` at `offset` to host memory, the same ways.
void readback(Context& ctx, const Buffer& src, void* data, uint64_t bytes, uint64_t offset = 0);
// Sets every 32-bit word of `dst` to `value` and waits.
void fill(Context& ctx, Buffer& dst, uint32_t value);

template <class T>
Buffer make_buffer(Context& ctx, std::span<const T> data, const std::string& name) {
  Buffer b(ctx, std::max<uint64_t>(data.size_bytes(), 4), MemoryUsage::Device, name);
  if (!data.empty()) upload(ctx, b, data.data(), data.size_bytes());
  return b;
}

}  // namespace tfm
