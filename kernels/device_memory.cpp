// The device-memory check (kernels/device_memory.h).
#include "tfmatch/kernels/device_memory.h"

#include <algorithm>
#include <stdexcept>

#include "tfmatch/engine/context.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {

void check_device_memory(const Context& ctx, uint64_t bytes, const std::string& what) {
  uint64_t largest_heap = 0;
  const VkPhysicalDeviceMemoryProperties& mem = ctx.memory_properties();
  for (uint32_t i = 0; i < mem.memoryHeapCount; ++i) largest_heap = std::max<uint64_t>(largest_heap, mem.memoryHeaps[i].size);
  if (bytes > largest_heap)
    throw std::runtime_error(what + ": needs " + format_bytes(bytes) + " of device memory, more than the largest memory heap of " +
                             ctx.device_name() + " (" + format_bytes(largest_heap) + ")");
  if (device_memory_is_host(ctx)) check_memory(bytes, what);
}

DeviceField field_over_host_values(Context& ctx, std::span<const float> values, const std::string& what,
                                   uint64_t max_chunk_voxels) {
  if (std::optional<DeviceField> in_place = DeviceField::in_host_memory(ctx, values, what, max_chunk_voxels))
    return std::move(*in_place);
  check_device_memory(ctx, values.size_bytes(), what);
  return DeviceField(ctx, values, what, max_chunk_voxels);
}

bool device_memory_is_host(const Context& ctx) {
  const VkPhysicalDeviceType type = ctx.properties().deviceType;
  return type == VK_PHYSICAL_DEVICE_TYPE_CPU || type == VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU;
}

}  // namespace tfm
