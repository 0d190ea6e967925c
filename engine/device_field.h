// A scalar field on the device, split into chunks that each fit one storage-buffer descriptor and
// one float32 texel-buffer view (maxStorageBufferRange is 128 MiB on lavapipe; a 10^8-voxel float
// field needs 400 MB).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "tfmatch/engine/buffer.h"

namespace tfm {

class Context;

// How a field's voxels are stored: what a texel fetch reads them as is the stored number (the
// float, the float16, or a unorm's c / (2^b - 1)); a value mapping (model: ValueMapping) turns
// stored numbers into field values. Fields tfmatch uploads are Float32; an embedder's buffer may
// be any of these (DeviceField::adopt).
enum class FieldFormat { Float32, Float16, Unorm16, Unorm8 };
uint32_t field_format_bytes(FieldFormat format);
VkFormat voxel_texel_format(FieldFormat format);  // one voxel a texel: R32_SFLOAT, R16_SFLOAT, R16_UNORM, R8_UNORM
VkFormat quad_texel_format(FieldFormat format);   // four voxels a texel: the RGBA formats of the same
const char* field_format_name(FieldFormat format);
// "R8G8B8A8_UNORM" for the formats a host is likely to hand tfmatch (the field and TF formats,
// their multi-channel and integer neighbours), else "VkFormat N": for messages.
std::string vk_format_name(VkFormat format);
// The FieldFormat of a one-channel image format the kernels read a field from (R32_SFLOAT,
// R16_SFLOAT, R16_UNORM, R8_UNORM); std::invalid_argument naming `what` and the format for any
// other.
FieldFormat field_format_of(VkFormat format, const char* what);

// A field format the device cannot read the way the kernels read fields: as uniform texel buffers
// of its one-voxel and four-voxel texel formats. Vulkan requires that of every device for float32,
// float16 and unorm8, not for unorm16 (R16_UNORM, R16G16B16A16_UNORM), which some devices lack;
// a kernel would then read whatever the driver makes of an unsupported view.
class UnsupportedFieldFormat : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// Empty when the device of `ctx` reads `format` as texels (one voxel a texel, and with `quads`
// four voxels a texel too, as the voxel-pair kernels read them), else which texel format it lacks.
std::string field_format_unsupported(const Context& ctx, FieldFormat format, bool quads = true);
// Throws UnsupportedFieldFormat naming `what`, the device and the texel format it lacks, with
// the formats it does read, where field_format_unsupported() says why not.
void require_field_format(const Context& ctx, FieldFormat format, const std::string& what, bool quads = true);

class DeviceField {
 public:
  // Voxels per chunk: the device limit, or `max_chunk_voxels` when smaller (tests force splits).
  DeviceField(Context& ctx, uint64_t voxel_count, const std::string& name, uint64_t max_chunk_voxels = 0);
  DeviceField(Context& ctx, std::span<const float> values, const std::string& name,
              uint64_t max_chunk_voxels = 0);
  // A field already on the device in a caller's buffer: `voxel_count` float32 values from byte
  // `offset` of `buffer`, chunked as the engine's own fields are, each chunk a view of the caller's
  // range (Buffer::adopt; the same alignment rule). Nothing is copied or allocated, on the device or
  // the host; the caller keeps the buffer alive, and unchanged while recorded work reads it.
  static DeviceField adopt(Context& ctx, VkBuffer buffer, uint64_t offset, uint64_t voxel_count,
                           const std::string& name, uint64_t max_chunk_voxels = 0,
                           FieldFormat format = FieldFormat::Float32);

  // The caller's float32 values in host memory as the field itself, nothing copied or allocated,
  // on a CPU device (lavapipe: its own memory is host memory too, so an upload is a copy of every
  // voxel into fresh memory, 307 ms and 332 MB more for two 41.5 M-voxel fields on 2 cores) that
  // imports host memory (Context::host_import()). The caller keeps `values` alive and unchanged
  // while the field is used. nullopt on other devices, or where the memory's placement does not
  // allow it (the import alignment above the page size, or the values' offset in their first page
  // not a multiple of the buffer offset alignments): then construct it from the values (a copy).
  static std::optional<DeviceField> in_host_memory(Context& ctx, std::span<const float> values,
                                                   const std::string& name, uint64_t max_chunk_voxels = 0);
  // Whether in_host_memory() can read host values in place on this device (a CPU device that
  // imports host memory), so that fields take no device memory of their own: for estimates made
  // before the values exist (in_host_memory still declines values whose placement does not allow it).
  static bool reads_host_memory(const Context& ctx);
  // Whether the field reads the caller's host memory (in_host_memory).
  bool in_host_memory() const { return static_cast<bool>(host_memory_); }

  // Float32 fields only (std::logic_error otherwise).
  void upload(std::span<const float> values);
  FieldFormat format() const { return format_; }
  uint64_t voxel_count() const { return voxels_; }
  uint64_t chunk_voxels() const { return chunk_voxels_; }  // every chunk but the last
  size_t chunk_count() const { return chunks_.size(); }
  const Buffer& chunk(size_t i) const { return chunks_[i]; }
  uint64_t chunk_begin(size_t i) const { return i * chunk_voxels_; }
  uint64_t chunk_size(size_t i) const;
  // Chunks for an array binding of `slots` descriptors, padded with the last chunk. Throws
  // std::runtime_error if the field has more chunks than slots.
  std::vector<const Buffer*> chunk_array(size_t slots) const;

 private:
  struct ChunkingOnly {};
  // Sets the chunking and checks the size; makes no buffers.
  DeviceField(ChunkingOnly, Context& ctx, uint64_t voxel_count, uint64_t max_chunk_voxels, const std::string& name);
  size_t planned_chunks() const { return static_cast<size_t>((voxels_ + chunk_voxels_ - 1) / chunk_voxels_); }
  Context* ctx_;
  FieldFormat format_ = FieldFormat::Float32;
  uint64_t voxels_ = 0;
  uint64_t chunk_voxels_ = 0;
  std::vector<Buffer> chunks_;
  Buffer host_memory_;  // in_host_memory(): the imported pages the chunks view
};

}  // namespace tfm
