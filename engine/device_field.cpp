// Chunked device fields.
#include "tfmatch/engine/device_field.h"

#include <unistd.h>

#include <algorithm>
#include <stdexcept>

#include "tfmatch/engine/context.h"

namespace tfm {

// The chunking alone (no buffers yet): both the owning constructor and adopt() start here.
DeviceField::DeviceField(ChunkingOnly, Context& ctx, uint64_t voxel_count, uint64_t max_chunk_voxels,
                         const std::string& name)
    : ctx_(&ctx), voxels_(voxel_count) {
  if (voxel_count == 0) throw std::invalid_argument("DeviceField '" + name + "': no voxels");
  // Chunks are whole multiples of 1024 voxels so chunk boundaries never split a workgroup's span.
  // Chunks fit one storage-buffer descriptor and one texel-buffer view of float32 texels (the
  // renderer and the assembly read fields as texels).
  uint64_t device_chunk =
      (std::min<uint64_t>(ctx.max_buffer_bytes() / sizeof(float), ctx.limits().maxTexelBufferElements)) / 1024 * 1024;
  chunk_voxels_ = std::min(device_chunk, voxel_count);
  if (max_chunk_voxels) chunk_voxels_ = std::min(chunk_voxels_, max_chunk_voxels);
  chunks_.reserve(planned_chunks());
}

DeviceField::DeviceField(Context& ctx, uint64_t voxel_count, const std::string& name, uint64_t max_chunk_voxels)
    : DeviceField(ChunkingOnly{}, ctx, voxel_count, max_chunk_voxels, name) {
  for (size_t i = 0; i < planned_chunks(); ++i)
    chunks_.emplace_back(ctx, chunk_size(i) * sizeof(float), MemoryUsage::Device,
                         name + " chunk " + std::to_string(i));
}

DeviceField DeviceField::adopt(Context& ctx, VkBuffer buffer, uint64_t offset, uint64_t voxel_count,
                               const std::string& name, uint64_t max_chunk_voxels, FieldFormat format) {
  require_field_format(ctx, format, "DeviceField '" + name + "'");
  DeviceField field(ChunkingOnly{}, ctx, voxel_count, max_chunk_voxels, name);
  field.format_ = format;
  const uint64_t bytes = field_format_bytes(format);
  for (size_t i = 0; i < field.planned_chunks(); ++i)
    field.chunks_.push_back(Buffer::adopt(ctx, buffer, offset + field.chunk_begin(i) * bytes,
                                          field.chunk_size(i) * bytes, name + " chunk " + std::to_string(i)));
  return field;
}

bool DeviceField::reads_host_memory(const Context& ctx) {
  return ctx.host_import() && ctx.properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
}

std::optional<DeviceField> DeviceField::in_host_memory(Context& ctx, std::span<const float> values,
                                                       const std::string& name, uint64_t max_chunk_voxels) {
  if (values.empty() || !reads_host_memory(ctx)) return std::nullopt;
  // The import takes whole aligned units around the values: no more than the pages they lie in,
  // which are mapped as a whole (a larger alignment could reach unmapped memory).
  const uint64_t align = ctx.min_import_alignment();
  const long page = ::sysconf(_SC_PAGESIZE);
  if (page <= 0 || align > uint64_t(page) || (align & (align - 1))) return std::nullopt;
  const uintptr_t first = reinterpret_cast<uintptr_t>(values.data()), last = first + values.size_bytes();
  const uintptr_t begin = first / align * align, end = (last + align - 1) / align * align;
  const VkPhysicalDeviceLimits& limits = ctx.limits();
  const uint64_t offset_align = std::max<uint64_t>(limits.minStorageBufferOffsetAlignment, limits.minTexelBufferOffsetAlignment);
  DeviceField field(ChunkingOnly{}, ctx, values.size(), max_chunk_voxels, name);
  for (size_t i = 0; i < field.planned_chunks(); ++i)
    if ((first - begin + field.chunk_begin(i) * sizeof(float)) % offset_align) return std::nullopt;
  // Kernels only read fields, so the caller's memory is never written through this import.
  field.host_memory_ = Buffer::import_host(ctx, reinterpret_cast<void*>(begin), end - begin, name + " (host memory)",
                                           /*kernels_read=*/true);
  if (!field.host_memory_) return std::nullopt;
  for (size_t i = 0; i < field.planned_chunks(); ++i)
    field.chunks_.push_back(Buffer::adopt(ctx, field.host_memory_.handle(),
                                          first - begin + field.chunk_begin(i) * sizeof(float),
                                          field.chunk_size(i) * sizeof(float), name + " chunk " + std::to_string(i)));
  return field;
}

uint32_t field_format_bytes(FieldFormat format) {
  switch (format) {
    case FieldFormat::Float32: return 4;
    case FieldFormat::Float16:
    case FieldFormat::Unorm16: return 2;
    case FieldFormat::Unorm8: return 1;
  }
  throw std::logic_error("unknown field format");
}

VkFormat voxel_texel_format(FieldFormat format) {
  switch (format) {
    case FieldFormat::Float32: return VK_FORMAT_R32_SFLOAT;
    case FieldFormat::Float16: return VK_FORMAT_R16_SFLOAT;
    case FieldFormat::Unorm16: return VK_FORMAT_R16_UNORM;
    case FieldFormat::Unorm8: return VK_FORMAT_R8_UNORM;
  }
  throw std::logic_error("unknown field format");
}

VkFormat quad_texel_format(FieldFormat format) {
  switch (format) {
    case FieldFormat::Float32: return VK_FORMAT_R32G32B32A32_SFLOAT;
    case FieldFormat::Float16: return VK_FORMAT_R16G16B16A16_SFLOAT;
    case FieldFormat::Unorm16: return VK_FORMAT_R16G16B16A16_UNORM;
    case FieldFormat::Unorm8: return VK_FORMAT_R8G8B8A8_UNORM;
  }
  throw std::logic_error("unknown field format");
}

const char* field_format_name(FieldFormat format) {
  switch (format) {
    case FieldFormat::Float32: return "float32";
    case FieldFormat::Float16: return "float16";
    case FieldFormat::Unorm16: return "unorm16";
    case FieldFormat::Unorm8: return "unorm8";
  }
  return "unknown";
}

std::string vk_format_name(VkFormat format) {
  switch (format) {
    case VK_FORMAT_UNDEFINED: return "UNDEFINED";
    case VK_FORMAT_R8_UNORM: return "R8_UNORM";
    case VK_FORMAT_R8_UINT: return "R8_UINT";
    case VK_FORMAT_R16_UNORM: return "R16_UNORM";
    case VK_FORMAT_R16_UINT: return "R16_UINT";
    case VK_FORMAT_R16_SFLOAT: return "R16_SFLOAT";
    case VK_FORMAT_R32_UINT: return "R32_UINT";
    case VK_FORMAT_R32_SINT: return "R32_SINT";
    case VK_FORMAT_R32_SFLOAT: return "R32_SFLOAT";
    case VK_FORMAT_R8G8B8A8_UNORM: return "R8G8B8A8_UNORM";
    case VK_FORMAT_R8G8B8A8_SRGB: return "R8G8B8A8_SRGB";
    case VK_FORMAT_B8G8R8A8_UNORM: return "B8G8R8A8_UNORM";
    case VK_FORMAT_R16G16B16A16_UNORM: return "R16G16B16A16_UNORM";
    case VK_FORMAT_R16G16B16A16_SFLOAT: return "R16G16B16A16_SFLOAT";
    case VK_FORMAT_R32G32B32A32_SFLOAT: return "R32G32B32A32_SFLOAT";
    case VK_FORMAT_R64_SFLOAT: return "R64_SFLOAT";
    default: return "VkFormat " + std::to_string(int(format));
  }
}

FieldFormat field_format_of(VkFormat format, const char* what) {
  switch (format) {
    case VK_FORMAT_R32_SFLOAT: return FieldFormat::Float32;
    case VK_FORMAT_R16_SFLOAT: return FieldFormat::Float16;
    case VK_FORMAT_R16_UNORM: return FieldFormat::Unorm16;
    case VK_FORMAT_R8_UNORM: return FieldFormat::Unorm8;
    default:
      throw std::invalid_argument(std::string(what) + ": image format " + vk_format_name(format) +
                                  " is not a field format (R32_SFLOAT, R16_SFLOAT, R16_UNORM or R8_UNORM)");
  }
}

std::string field_format_unsupported(const Context& ctx, FieldFormat format, bool quads) {
  for (VkFormat texel : {voxel_texel_format(format), quad_texel_format(format)}) {
    if (!(ctx.buffer_format_features(texel) & VK_FORMAT_FEATURE_UNIFORM_TEXEL_BUFFER_BIT))
      return "the device reads no uniform texel buffer of " + vk_format_name(texel);
    if (!quads) break;
  }
  return {};
}

void require_field_format(const Context& ctx, FieldFormat format, const std::string& what, bool quads) {
  const std::string why = field_format_unsupported(ctx, format, quads);
  if (why.empty()) return;
  std::string readable;
  for (FieldFormat f : {FieldFormat::Float32, FieldFormat::Float16, FieldFormat::Unorm16, FieldFormat::Unorm8})
    if (field_format_unsupported(ctx, f, quads).empty()) readable += std::string(readable.empty() ? "" : ", ") + field_format_name(f);
  throw UnsupportedFieldFormat(what + ": " + field_format_name(format) + " fields cannot be read on " + ctx.device_name() +
                               " (" + why + "); it reads " + (readable.empty() ? "none" : readable) +
                               ": store the field in one of those");
}

DeviceField::DeviceField(Context& ctx, std::span<const float> values, const std::string& name,
                         uint64_t max_chunk_voxels)
    : DeviceField(ctx, values.size(), name, max_chunk_voxels) {
  upload(values);
}

uint64_t DeviceField::chunk_size(size_t i) const {
  return std::min(chunk_voxels_, voxels_ - chunk_begin(i));
}

void DeviceField::upload(std::span<const float> values) {
  if (format_ != FieldFormat::Float32)
    throw std::logic_error(std::string("DeviceField::upload: the field stores ") + field_format_name(format_) +
                           ", not float32 (it is the caller's buffer: write it there)");
  if (host_memory_) throw std::logic_error("DeviceField::upload: the field is the caller's host memory (in_host_memory): write the values there");
  if (values.size() != voxels_) throw std::invalid_argument("DeviceField::upload: size mismatch");
  for (size_t i = 0; i < chunks_.size(); ++i)
    tfm::upload(*ctx_, chunks_[i], values.data() + chunk_begin(i), chunk_size(i) * sizeof(float));
}

std::vector<const Buffer*> DeviceField::chunk_array(size_t slots) const {
  if (chunks_.size() > slots)
    throw std::runtime_error("field needs " + std::to_string(chunks_.size()) + " buffers but the kernel binds " +
                             std::to_string(slots) + " (volume too large for this device)");
  std::vector<const Buffer*> out;
  for (size_t i = 0; i < slots; ++i) out.push_back(&chunks_[std::min(i, chunks_.size() - 1)]);
  return out;
}

}  // namespace tfm
