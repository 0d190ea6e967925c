// Buffer allocation and staged transfers.
#include "tfmatch/engine/buffer.h"

#include <algorithm>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <utility>

#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/vk_check.h"
#include "tfmatch/engine/vk_dispatch.h"
#include "tfmatch/model/phase_timer.h"

namespace tfm {
namespace {

// The first allowed type with every `required` flag: one that also has every `preferred` flag and
// none of `avoided`, else one with the preferred flags, else any.
std::optional<uint32_t> find_memory_type(const VkPhysicalDeviceMemoryProperties& mem, uint32_t allowed,
                                         VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred,
                                         VkMemoryPropertyFlags avoided = 0) {
  std::optional<uint32_t> preferred_only, fallback;
  for (uint32_t i = 0; i < mem.memoryTypeCount; ++i) {
    if (!(allowed & (1u << i))) continue;
    VkMemoryPropertyFlags flags = mem.memoryTypes[i].propertyFlags;
    if ((flags & required) != required) continue;
    if ((flags & preferred) == preferred && !(flags & avoided)) return i;
    if ((flags & preferred) == preferred && !preferred_only) preferred_only = i;
    if (!fallback) fallback = i;
  }
  return preferred_only ? preferred_only : fallback;
}

}  // namespace

Buffer::Buffer(Context& ctx, uint64_t bytes, MemoryUsage usage, const std::string& debug_name)
    : ctx_(&ctx), bytes_(bytes) {
  if (bytes == 0) throw std::invalid_argument("Buffer '" + debug_name + "': size 0");
  const auto& vk = ctx.vk();
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = bytes;
  // Every buffer may also be read as a uniform texel buffer (DescriptorKind::UniformTexelBuffer).
  info.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT |
               VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  // A size past every memory heap fails in vkCreateBuffer or vkAllocateMemory with a bare
  // VK_ERROR_OUT_OF_DEVICE_MEMORY; say what was asked and what the device has instead.
  uint64_t largest_heap = 0;
  const VkPhysicalDeviceMemoryProperties& heaps = ctx.memory_properties();
  for (uint32_t i = 0; i < heaps.memoryHeapCount; ++i) largest_heap = std::max<uint64_t>(largest_heap, heaps.memoryHeaps[i].size);
  if (bytes > largest_heap)
    throw VulkanError("buffer '" + debug_name + "': " + std::to_string(bytes) + " bytes asked for, more than the " +
                          "device's largest memory heap (" + std::to_string(largest_heap) + " bytes)",
                      VK_ERROR_OUT_OF_DEVICE_MEMORY);
  const VkResult created = vk.vkCreateBuffer(ctx.device(), &info, nullptr, &buffer_);
  if (created != VK_SUCCESS)
    throw VulkanError("creating buffer '" + debug_name + "' of " + std::to_string(bytes) + " bytes failed with " +
                          vk_result_name(created),
                      created);
  ctx.set_debug_name(VK_OBJECT_TYPE_BUFFER, reinterpret_cast<uint64_t>(buffer_), debug_name.c_str());

  VkMemoryRequirements req{};
  vk.vkGetBufferMemoryRequirements(ctx.device(), buffer_, &req);
  VkMemoryPropertyFlags required = 0, preferred = 0, avoided = 0;
  switch (usage) {
    case MemoryUsage::Device: preferred = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT; break;
    case MemoryUsage::Upload:
      required = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
      // System memory, which the copy engine reads at full speed, rather than device memory seen
      // through the PCIe BAR (resizable BAR exposes all of it), where every host write crosses
      // the bus uncached; unified-memory devices have only device-local types and take those.
      avoided = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
      break;
    case MemoryUsage::Readback:
      required = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
      preferred = VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
      break;
  }
  auto type = find_memory_type(ctx.memory_properties(), req.memoryTypeBits, required, preferred, avoided);
  if (!type) {
    release();
    throw std::runtime_error("Buffer '" + debug_name + "': no suitable memory type");
  }
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.allocationSize = req.size;
  alloc.memoryTypeIndex = *type;
  VkResult r = vk.vkAllocateMemory(ctx.device(), &alloc, nullptr, &memory_);
  if (r != VK_SUCCESS) {
    release();
    throw VulkanError("allocating " + std::to_string(bytes) + " bytes for buffer '" + debug_name +
                          "' failed with " + vk_result_name(r),
                      r);
  }
  ctx.track_buffer_bytes(int64_t(bytes_));
  ctx.track_buffer_memory(1);
  VK_CHECK(vk.vkBindBufferMemory(ctx.device(), buffer_, memory_, 0));
  // Host buffers stay mapped for their lifetime. Device buffers are never mapped, even where
  // device memory is host-visible (lavapipe, integrated GPUs): transfers always take the same
  // staged path, so what CI tests is what runs on discrete GPUs.
  if (usage != MemoryUsage::Device)
    VK_CHECK(vk.vkMapMemory(ctx.device(), memory_, 0, VK_WHOLE_SIZE, 0, &mapped_));
}

Buffer Buffer::import_host(Context& ctx, void* pointer, uint64_t bytes, const std::string& debug_name,
                           bool kernels_read) {
  const uint64_t align = ctx.min_import_alignment();
  if (!align || !bytes || reinterpret_cast<uintptr_t>(pointer) % align || bytes % align) return {};
  const auto& vk = ctx.vk();
  VkMemoryHostPointerPropertiesEXT host_props{VK_STRUCTURE_TYPE_MEMORY_HOST_POINTER_PROPERTIES_EXT};
  if (vk.vkGetMemoryHostPointerPropertiesEXT(ctx.device(), VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT,
                                             pointer, &host_props) != VK_SUCCESS)
    return {};
  Buffer b;
  b.ctx_ = &ctx;
  b.bytes_ = bytes;
  b.tracked_ = false;
  VkExternalMemoryBufferCreateInfo external{VK_STRUCTURE_TYPE_EXTERNAL_MEMORY_BUFFER_CREATE_INFO};
  external.handleTypes = VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT;
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.pNext = &external;
  info.size = bytes;
  info.usage = VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
  if (kernels_read) info.usage |= VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  if (vk.vkCreateBuffer(ctx.device(), &info, nullptr, &b.buffer_) != VK_SUCCESS) return {};
  ctx.set_debug_name(VK_OBJECT_TYPE_BUFFER, reinterpret_cast<uint64_t>(b.buffer_), debug_name.c_str());
  VkMemoryRequirements req{};
  vk.vkGetBufferMemoryRequirements(ctx.device(), b.buffer_, &req);
  // Host-coherent, so that what the device wrote is what the host then reads through `pointer`,
  // which is never mapped (no flush or invalidate to make).
  const auto type = find_memory_type(ctx.memory_properties(), host_props.memoryTypeBits & req.memoryTypeBits,
                                     VK_MEMORY_PROPERTY_HOST_COHERENT_BIT, 0);
  if (!type || req.size > bytes) return {};  // the destructor releases the buffer
  VkImportMemoryHostPointerInfoEXT import{VK_STRUCTURE_TYPE_IMPORT_MEMORY_HOST_POINTER_INFO_EXT};
  import.handleType = VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT;
  import.pHostPointer = pointer;
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.pNext = &import;
  alloc.allocationSize = bytes;
  alloc.memoryTypeIndex = *type;
  if (vk.vkAllocateMemory(ctx.device(), &alloc, nullptr, &b.memory_) != VK_SUCCESS) {
    b.memory_ = VK_NULL_HANDLE;
    return {};
  }
  ctx.track_buffer_memory(1);
  if (vk.vkBindBufferMemory(ctx.device(), b.buffer_, b.memory_, 0) != VK_SUCCESS) return {};
  return b;
}

Buffer Buffer::adopt(Context& ctx, VkBuffer buffer, uint64_t offset, uint64_t bytes, const std::string& what) {
  if (buffer == VK_NULL_HANDLE) throw std::invalid_argument(what + ": no buffer (VK_NULL_HANDLE)");
  if (bytes == 0) throw std::invalid_argument(what + ": an empty range");
  const VkPhysicalDeviceLimits& limits = ctx.limits();
  const uint64_t align = std::max<uint64_t>(limits.minStorageBufferOffsetAlignment, limits.minTexelBufferOffsetAlignment);
  if (offset % align)
    throw std::invalid_argument(what + ": offset " + std::to_string(offset) + " is not a multiple of " +
                                std::to_string(align) + " (the device's storage/texel buffer offset alignment)");
  // Vulkan does not tell a buffer's size from its handle, but its memory requirement is at least
  // that size: a range past it is past the buffer (a field of 4096 voxels over a buffer of 1000
  // floats had been recorded, and read out of bounds).
  VkMemoryRequirements req{};
  ctx.vk().vkGetBufferMemoryRequirements(ctx.device(), buffer, &req);
  if (offset > req.size || bytes > req.size - offset)
    throw std::invalid_argument(what + ": bytes " + std::to_string(offset) + " to " + std::to_string(offset + bytes) +
                                " pass the end of the buffer (its memory requirement is " + std::to_string(req.size) +
                                " bytes)");
  Buffer b;
  b.ctx_ = &ctx;
  b.buffer_ = buffer;
  b.offset_ = offset;
  b.bytes_ = bytes;
  b.tracked_ = false;
  b.owned_ = false;
  return b;
}

Buffer::~Buffer() { release(); }

Buffer::Buffer(Buffer&& o) noexcept { *this = std::move(o); }

Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    release();
    ctx_ = std::exchange(o.ctx_, nullptr);
    buffer_ = std::exchange(o.buffer_, VK_NULL_HANDLE);
    memory_ = std::exchange(o.memory_, VK_NULL_HANDLE);
    offset_ = std::exchange(o.offset_, 0);
    bytes_ = std::exchange(o.bytes_, 0);
    mapped_ = std::exchange(o.mapped_, nullptr);
    tracked_ = std::exchange(o.tracked_, true);
    owned_ = std::exchange(o.owned_, true);
  }
  return *this;
}

void Buffer::release() {
  if (!ctx_) return;
  if (!owned_) {
    buffer_ = VK_NULL_HANDLE;
    return;
  }
  const auto& vk = ctx_->vk();
  if (mapped_) vk.vkUnmapMemory(ctx_->device(), memory_);
  if (buffer_) vk.vkDestroyBuffer(ctx_->device(), buffer_, nullptr);
  if (memory_) {
    vk.vkFreeMemory(ctx_->device(), memory_, nullptr);
    ctx_->track_buffer_memory(-1);
    if (tracked_) ctx_->track_buffer_bytes(-int64_t(bytes_));
  }
  buffer_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  mapped_ = nullptr;
}

namespace {

void staged_upload(Context& ctx, Buffer& dst, const void* data, uint64_t bytes, uint64_t offset);
void staged_readback(Context& ctx, const Buffer& src, void* data, uint64_t bytes, uint64_t offset);

// Copies between `device` at `device_offset` and `bytes` of host memory at `host`: the interior
// that starts and ends on the import alignment straight from or to the host memory, the two
// unaligned ends (less than an alignment each) through staging while that copy runs. Returns false,
// having copied nothing, when the transfer is small or the memory cannot be imported.
bool direct_transfer(Context& ctx, const Buffer& device, uint64_t device_offset, void* host, uint64_t bytes,
                     bool to_device) {
  if (!ctx.host_import() || bytes < kHostImportMinBytes) return false;
  const uint64_t align = ctx.min_import_alignment();
  const uintptr_t first = reinterpret_cast<uintptr_t>(host);
  const uintptr_t begin = (first + align - 1) / align * align, end = (first + bytes) / align * align;
  if (end <= begin) return false;
  Buffer imported = Buffer::import_host(ctx, reinterpret_cast<void*>(begin), end - begin,
                                        to_device ? "imported upload" : "imported readback");
  if (!imported) return false;
  const uint64_t head = begin - first, tail = first + bytes - end;
  CommandBatch batch(ctx);
  if (to_device) batch.copy(imported, 0, device, device_offset + head, end - begin);
  else batch.copy(device, device_offset + head, imported, 0, end - begin);
  batch.submit();
  char* const bytes_at = static_cast<char*>(host);
  // Buffer is only read by a readback and written by an upload; the const_cast is the upload's.
  Buffer& target = const_cast<Buffer&>(device);
  if (head) {
    if (to_device) staged_upload(ctx, target, bytes_at, head, device_offset);
    else staged_readback(ctx, device, bytes_at, head, device_offset);
  }
  if (tail) {
    if (to_device) staged_upload(ctx, target, bytes_at + bytes - tail, tail, device_offset + bytes - tail);
    else staged_readback(ctx, device, bytes_at + bytes - tail, tail, device_offset + bytes - tail);
  }
  batch.wait();  // the host memory is the caller's again
  return true;
}

}  // namespace

void upload(Context& ctx, Buffer& dst, const void* data, uint64_t bytes, uint64_t offset) {
  if (offset + bytes > dst.size()) throw std::out_of_range("upload past the end of a buffer");
  PhaseScope timing(Phase::Upload);
  if (dst.host_visible()) {
    std::memcpy(static_cast<char*>(dst.mapped()) + offset, data, bytes);
    return;
  }
  // Imported memory is only read by the device here (the copy's source).
  if (direct_transfer(ctx, dst, offset, const_cast<void*>(data), bytes, true)) return;
  staged_upload(ctx, dst, data, bytes, offset);
}

void readback(Context& ctx, const Buffer& src, void* data, uint64_t bytes, uint64_t offset) {
  if (offset + bytes > src.size()) throw std::out_of_range("readback past the end of a buffer");
  PhaseScope timing(Phase::Download);
  if (src.host_visible()) {
    std::memcpy(data, static_cast<const char*>(src.mapped()) + offset, bytes);
    return;
  }
  if (direct_transfer(ctx, src, offset, data, bytes, false)) return;
  staged_readback(ctx, src, data, bytes, offset);
}

namespace {

void staged_upload(Context& ctx, Buffer& dst, const void* data, uint64_t bytes, uint64_t offset) {
  // The two staging halves in turn: the host fills one while the device copies the other (a
  // DMA transfer on a discrete GPU; the driver's queue thread on lavapipe).
  StagingBuffers& staging = ctx.staging();
  std::lock_guard lock(staging.mutex);
  const uint64_t half = std::min(bytes, kStagingBytes / 2);
  std::optional<CommandBatch> copies[2];
  uint64_t piece = 0;
  for (uint64_t done = 0; done < bytes; done += half, ++piece) {
    const size_t slot = piece % 2;
    if (copies[slot]) copies[slot].reset();  // waits until the device has read this half
    Buffer& stage = staging.half[slot];
    if (!stage || stage.size() < half) {
      stage = Buffer();  // the old one first: the footprint stays bounded
      stage = Buffer(ctx, half, MemoryUsage::Upload, "staging upload");
    }
    const uint64_t n = std::min(half, bytes - done);
    std::memcpy(stage.mapped(), static_cast<const char*>(data) + done, n);
    copies[slot].emplace(ctx);
    copies[slot]->copy(stage, 0, dst, offset + done, n);
    copies[slot]->submit();
  }
  for (auto& c : copies)
    if (c) c->wait();
}

void staged_readback(Context& ctx, const Buffer& src, void* data, uint64_t bytes, uint64_t offset) {
  Buffer staging(ctx, std::min(bytes, kStagingBytes), MemoryUsage::Readback, "staging readback");
  for (uint64_t done = 0; done < bytes; done += staging.size()) {
    uint64_t n = std::min(staging.size(), bytes - done);
    CommandBatch batch(ctx);
    batch.copy(src, offset + done, staging, 0, n);
    batch.submit_and_wait();
    std::memcpy(static_cast<char*>(data) + done, staging.mapped(), n);
  }
}

}  // namespace

void fill(Context& ctx, Buffer& dst, uint32_t value) {
  CommandBatch batch(ctx);
  batch.fill(dst, value);
  batch.submit_and_wait();
}

}  // namespace tfm
