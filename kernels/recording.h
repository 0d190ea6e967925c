// tfmatch's work recorded into a host's command buffers (DESIGN.md "Where the data lives"): a
// renderer that already holds its volumes on the device re-fits a TF inside its own frame. The
// queue stays the host's: nothing here submits or waits. Each record_* call states what it reads
// and writes and in which pipeline stages (RecordedAccess); the host orders its own work against
// that with its barriers or semaphores, submits the command buffer itself, and reads the small
// result (O(N): M, Sᵀb, bᵀb) after its own fence or timeline-semaphore wait.
//
// The per-frame protocol (tools/examples/renderer and tests/engine/test_embedding_recording*.cpp):
//   frame k:   host barrier (its writes of the volumes -> compute-shader reads)
//              recorder.record_assemble(cmd, ref, opt, maps, reference TF)
//              host submits cmd with its fence
//   frame k+1: host waits for that fence; eq = recorder.result(); x = solve_normal_equations(eq)
//              uploader.record_tf_upload(cmd, x, the host's TF image or buffer), host samples it
// A recorder keeps the descriptor sets of its last recording until the next one, so each
// submission in flight needs its own recorder (one per frame in flight, as the host's command
// buffers are); record again only after the host's wait for the previous recording returned.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <vulkan/vulkan_core.h>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/assemble_normal_equations.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/normal_equations_system.h"

namespace tfm {

class CommandBatch;
class Context;
class RenderImageKernel;
class ResidualMapKernel;
class VoxelLossKernel;

// What a recorded operation does to memory the host shares with it.
struct RecordedAccess {
  VkPipelineStageFlags stages = 0;  // the stages its commands run in
  VkAccessFlags reads = 0;          // how it reads the host's resources (volumes, TF) there
  VkAccessFlags writes = 0;         // how it writes the host's resources there (0: only its own)
};

// Scratch memory a host lends a recorder instead of the recorder's own (a renderer that
// sub-allocates everything from its own heaps): a device range for the accumulators and a
// host-visible, host-coherent range, mapped by the host at `result_mapped`, for the result the
// host reads after its wait. Sizes: NormalEquationsRecorder::scratch_bytes,
// VoxelLossRecorder::scratch_bytes. Offsets must meet the
// device's storage-buffer offset alignment; the buffers need storage and transfer usages.
struct RecorderScratch {
  VkBuffer accumulators = VK_NULL_HANDLE;
  uint64_t accumulators_offset = 0;
  VkBuffer result = VK_NULL_HANDLE;
  uint64_t result_offset = 0;
  const void* result_mapped = nullptr;  // the host's mapping of `result` at `result_offset`
};

class NormalEquationsRecorder {
 public:
  // Creates the accumulators (device), the result's host-visible copy and the reference-TF table
  // once; pipelines are made on the first recording. Throws as GpuNormalEquations does.
  NormalEquationsRecorder(Context& ctx, uint32_t tf_size, ReductionOptions options = {});
  // The same in the host's scratch memory (the reference-TF table, O(N) bytes, stays the
  // recorder's). Throws std::invalid_argument for a missing buffer or mapping or a misaligned
  // offset.
  NormalEquationsRecorder(Context& ctx, uint32_t tf_size, const RecorderScratch& scratch, ReductionOptions options = {});
  // Bytes of each scratch range for `tf_size` entries: the accumulators and the result alike.
  static uint64_t scratch_bytes(uint32_t tf_size);
  ~NormalEquationsRecorder();
  NormalEquationsRecorder(const NormalEquationsRecorder&) = delete;
  NormalEquationsRecorder& operator=(const NormalEquationsRecorder&) = delete;

  // Records into `cmd` (recording, from a pool of the context's queue family): the reference TF
  // `ref_tf_rgba` (N_r RGBA entries as 4 N_r floats, written inside the command buffer into the
  // recorder's own table), zeroed accumulators, the assembly of (ref, opt) with the same kernels
  // and bits as GpuNormalEquations, and the copy of the result into host-visible memory with a
  // barrier that makes it visible to the host after its wait. `ref` and `opt` may be the host's
  // buffers (DeviceField::adopt). Reads them in the compute-shader stage (access()); the host's
  // writes to them must be ordered before with its own barrier. Throws std::invalid_argument for
  // sizes that do not match (fields, mappings, TF).
  void record_assemble(VkCommandBuffer cmd, const DeviceField& ref, const DeviceField& opt,
                       const FieldMapping& ref_map, const FieldMapping& opt_map, std::span<const float> ref_tf_rgba);
  // The same reading two of the host's 3D images in place (assemble_normal_equations.h's
  // ImageFieldView: no copy, no memory of the volume's size): the same bits as the same values in
  // buffers. The images must be in their stated layouts (SHADER_READ_ONLY_OPTIMAL or GENERAL),
  // with VK_IMAGE_USAGE_SAMPLED_BIT, the host's writes ordered before compute-shader reads.
  void record_assemble(VkCommandBuffer cmd, const ImageFieldView& ref, const ImageFieldView& opt,
                       const FieldMapping& ref_map, const FieldMapping& opt_map, std::span<const float> ref_tf_rgba);
  // The system of the last recording, once the host's wait for its submission returned (before
  // that the numbers are undefined). std::logic_error before any recording.
  NormalEquations result() const;
  // Its exact totals (GpuNormalEquations::fixed_point_slots): equal bits prove equal systems.
  std::vector<uint64_t> fixed_point_slots() const;
  // record_assemble reads the host's fields in the compute-shader stage and writes only the
  // recorder's own memory (transfer and compute stages, made visible to the host).
  static RecordedAccess access();
  uint32_t tf_size() const;

 private:
  std::vector<uint32_t> result_words() const;
  void record_with(VkCommandBuffer cmd, const FieldMapping& opt_map, const FieldMapping& ref_map,
                   std::span<const float> ref_tf_rgba, const std::function<void(CommandBatch&)>& assemble);
  Context& ctx_;
  std::unique_ptr<AssembleNormalEquationsKernel> kernel_;
  Buffer accum_, result_, ref_tf_;
  const void* result_mapped_ = nullptr;  // result_'s mapping: the recorder's or the host's
  std::unique_ptr<CommandBatch> recording_;  // the last recording's descriptor sets and views
  bool recorded_ = false;
};

// The residual map of DESIGN.md, per voxel || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2, recorded
// into a field the host can render as it renders its volumes (e.g. its own buffer through
// DeviceField::adopt, chunked like the inputs).
class ResidualMapRecorder {
 public:
  explicit ResidualMapRecorder(Context& ctx);
  ~ResidualMapRecorder();
  ResidualMapRecorder(const ResidualMapRecorder&) = delete;
  ResidualMapRecorder& operator=(const ResidualMapRecorder&) = delete;

  // Records the two TF tables (written inside the command buffer) and the map into `out`: the
  // same kernel and bits as residual_map_gpu(). Throws std::invalid_argument when the fields
  // differ in size or chunking, or a table does not match its mapping.
  void record_residual_map(VkCommandBuffer cmd, const DeviceField& ref, const DeviceField& opt,
                           const FieldMapping& ref_map, const FieldMapping& opt_map, std::span<const float> ref_tf_rgba,
                           std::span<const float> opt_tf_rgba, DeviceField& out);
  // The same from two of the host's 3D images read in place (ImageFieldView), into `out` holding
  // the volume's voxels in one chunk (a renderer's residual volume): the same bits as from buffers.
  void record_residual_map(VkCommandBuffer cmd, const ImageFieldView& ref, const ImageFieldView& opt,
                           const FieldMapping& ref_map, const FieldMapping& opt_map, std::span<const float> ref_tf_rgba,
                           std::span<const float> opt_tf_rgba, DeviceField& out);
  // Reads `ref` and `opt` and writes `out` in the compute-shader stage.
  static RecordedAccess access();

 private:
  Context& ctx_;
  std::unique_ptr<ResidualMapKernel> kernel_;
  Buffer ref_tf_, opt_tf_;
  std::unique_ptr<CommandBatch> recording_;
};

// tfmatch's renderer (the one the optimizers and reports use: DESIGN.md's optical model, one
// RenderSettings), recorded into the host's command buffer: the picture a host shows beside its
// own, rendered exactly as tfmatch's images and DiffDVR see the field.
class RenderRecorder {
 public:
  // For fields of `geometry` split into `field_chunks` chunks (a field's chunk_count()).
  RenderRecorder(Context& ctx, const VolumeGeometry& geometry, uint32_t field_chunks);
  // The same with the per-pixel stop indices (4 bytes a pixel, device-local) in the host's memory:
  // `bytes` of `buffer` from `offset` (storage usage, the device's storage-buffer offset
  // alignment), for images of up to bytes / 4 pixels. The TF table and the camera (O(N), 64 bytes)
  // stay the recorder's.
  RenderRecorder(Context& ctx, const VolumeGeometry& geometry, uint32_t field_chunks, VkBuffer stop_scratch,
                 uint64_t offset, uint64_t bytes);
  static uint64_t stop_scratch_bytes(uint32_t width, uint32_t height) { return uint64_t(width) * height * 4; }
  ~RenderRecorder();
  RenderRecorder(const RenderRecorder&) = delete;
  RenderRecorder& operator=(const RenderRecorder&) = delete;

  // Records the TF table, the camera and the ray march of `settings` (camera, image size, step,
  // opacity scale, termination) into `image`: width x height premultiplied linear RGBA float
  // pixels (16 bytes each, row 0 first), e.g. the host's buffer through Buffer::adopt. The same
  // kernel and bits as GpuRenderer::render_colours. Throws as it does (settings, sizes).
  void record_render(VkCommandBuffer cmd, const DeviceField& field, const FieldMapping& mapping,
                     std::span<const float> tf_rgba, const RenderSettings& settings, Buffer& image);
  // The same from the host's 3D image read in place (ImageFieldView; its extent the geometry's
  // grid): no copy, the same samples and bits as the same values in a field's buffers.
  void record_render(VkCommandBuffer cmd, const ImageFieldView& field, const FieldMapping& mapping,
                     std::span<const float> tf_rgba, const RenderSettings& settings, Buffer& image);
  // Reads the field in the compute-shader stage and writes `image` there (shader write).
  static RecordedAccess access();

 private:
  Context& ctx_;
  VolumeGeometry geometry_;
  std::unique_ptr<RenderImageKernel> kernel_, image_kernel_;  // the image variant when first used
  Buffer tf_, views_, stop_;
  bool host_stop_ = false;  // stop_ is the host's scratch (never grown)
  std::unique_ptr<CommandBatch> recording_;
  template <class Field>
  void record_picture(VkCommandBuffer cmd, const RenderImageKernel& kernel, const Field& field,
                      const FieldMapping& mapping, std::span<const float> tf_rgba, const RenderSettings& settings,
                      Buffer& image);
};

// A host's volume held as a 3D image (R32_SFLOAT, R16_SFLOAT, R16_UNORM, R8_UNORM: DeviceField's
// formats), described for ImageFieldRecorder. Its texel (x, y, z) is voxel (z ny + y) nx + x.
struct ImageFieldSource {
  VkImage image = VK_NULL_HANDLE;  // 3D, mip 0 and layer 0 used, with VK_IMAGE_USAGE_TRANSFER_SRC_BIT
  VkFormat format = VK_FORMAT_R32_SFLOAT;
  VkExtent3D extent{0, 0, 0};
  VkImageLayout layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;  // its layout, before and after
  // The host's last writes of the image, ordered before the copy (e.g. its upload: transfer stage,
  // transfer write), and its next use after it (e.g. its renderer's shader reads).
  VkPipelineStageFlags src_stages = VK_PIPELINE_STAGE_TRANSFER_BIT;
  VkAccessFlags src_access = VK_ACCESS_TRANSFER_WRITE_BIT;
  VkPipelineStageFlags dst_stages = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
  VkAccessFlags dst_access = VK_ACCESS_SHADER_READ_BIT;
};

// A host's 3D image as a field every recorder above reads (the assembly, voxel loss, residual map
// and rendering also read images in place, their record_* with ImageFieldView; an ensemble of
// member images goes to CorrelationRecorder's image overload). tfmatch's voxel kernels read fields as texel
// buffers, four voxels a texel (DESIGN.md: a texel fetch is a vector gather on CPU devices and a
// cached load on GPUs), which an image cannot be viewed as; so record_copy() copies the image on
// the device (vkCmdCopyImageToBuffer, the stored texels unchanged: the same bits as the host's
// values in a buffer) into the recorder's buffer, or the host's, of the image's size in its own
// format (2 bytes a voxel for R16). Nothing goes through the host. The cost is that device memory
// and one device-local copy per recording (tools/examples/renderer measures a frame with it
// beside one reading the images in place: docs/embedding.md).
class ImageFieldRecorder {
 public:
  // The field's buffer is the recorder's (created once). Throws std::invalid_argument for a
  // format DeviceField lacks or an empty extent.
  ImageFieldRecorder(Context& ctx, VkExtent3D extent, VkFormat format, const std::string& name,
                     uint64_t max_chunk_voxels = 0);
  // The field's buffer is the host's: `bytes_needed(extent, format)` bytes of `buffer` from
  // `offset` (a multiple of the device's texel-buffer offset alignment, as DeviceField::adopt
  // requires), with transfer-destination and uniform-texel-buffer usages.
  ImageFieldRecorder(Context& ctx, VkExtent3D extent, VkFormat format, const std::string& name, VkBuffer buffer,
                     uint64_t offset, uint64_t max_chunk_voxels = 0);
  static uint64_t bytes_needed(VkExtent3D extent, VkFormat format);
  ~ImageFieldRecorder();
  ImageFieldRecorder(const ImageFieldRecorder&) = delete;
  ImageFieldRecorder& operator=(const ImageFieldRecorder&) = delete;

  // Records the copy of `source` (its extent and format those of the constructor, else
  // std::invalid_argument) into the field, with the layout changes and barriers its description
  // states, made visible to compute-shader reads: record any recorder's work on field() after it
  // in the same command buffer (or a later one). A copy keeps no descriptors, so unlike the other
  // recorders one ImageFieldRecorder serves every frame in flight (its barriers order a copy after
  // the reads of the last one: submission order on the one queue).
  void record_copy(VkCommandBuffer cmd, const ImageFieldSource& source);
  // The field the copies land in: pass it to the recorders. Valid as long as the recorder lives.
  const DeviceField& field() const { return field_; }
  // Reads the host's image in the transfer stage; writes only the field's buffer there.
  static RecordedAccess access();

 private:
  Context& ctx_;
  VkExtent3D extent_;
  FieldFormat format_;
  Buffer own_;  // the field's memory when it is the recorder's
  DeviceField field_;
  std::unique_ptr<CommandBatch> recording_;
};

// A correlation field (kernels/correlation.h) of an ensemble already on the device, recorded: the
// host's buffer of M x V floats, member-major (member m's voxel v at m * V + v).
class CorrelationRecorder {
 public:
  // `max_chunk_voxels`: chunks of an ensemble beyond one texel view (CorrelationKernel::record),
  // at most this many voxels when given (tests force chunks).
  explicit CorrelationRecorder(Context& ctx, uint64_t max_chunk_voxels = 0);
  // The same with the chunks (of ensembles beyond one texel view, and of member images) in the
  // host's memory: `bytes` of `buffer` from `offset` (storage, uniform-texel and transfer-
  // destination usages; the device's texel-buffer offset alignment), at least
  // CorrelationKernel::min_chunk_bytes(members, format) for the ensembles it will record (else
  // record_correlation throws std::invalid_argument). The reference's tables (O(M)) stay the
  // recorder's.
  CorrelationRecorder(Context& ctx, VkBuffer chunk_scratch, uint64_t offset, uint64_t bytes,
                      uint64_t max_chunk_voxels = 0);
  ~CorrelationRecorder();
  CorrelationRecorder(const CorrelationRecorder&) = delete;
  CorrelationRecorder& operator=(const CorrelationRecorder&) = delete;

  // Records the reference's tables (prepared on the host from `reference_series`, the M values at
  // the reference point, which the host has: nothing is read back) and the field of
  // `params.measure` into `out` (`voxels` floats): the same kernels and bits as
  // CorrelationKernel::compute on the same values; an ensemble beyond one texel view is read in
  // chunks copied on the device (CorrelationKernel::record). Throws std::invalid_argument for bad
  // params or sizes.
  void record_correlation(VkCommandBuffer cmd, const Buffer& ensemble, uint64_t voxels,
                          std::span<const float> reference_series, const CorrelationParams& params, Buffer& out);
  // The same for a buffer of members x voxels values of `format` (float16 halves the memory of a
  // float32 ensemble; unorm16 and unorm8 correlate the stored numbers c / (2^b - 1), which is what
  // `reference_series` must hold too: kernels/correlation.h's DeviceEnsemble).
  void record_correlation(VkCommandBuffer cmd, const Buffer& ensemble, FieldFormat format, uint64_t voxels,
                          std::span<const float> reference_series, const CorrelationParams& params, Buffer& out);
  // The same for an ensemble held as one 3D image per member (ImageFieldSource each, all of one
  // extent and format; `out` gets the extent's voxel count of floats): the images are copied
  // chunk by chunk on the device, in their own format, into the recorder's member-major chunk
  // (at most maxTexelBufferElements values, or max_chunk_voxels per member) and read from there
  // with the same kernels and bits as the same stored numbers in a buffer. Each image moves to
  // TRANSFER_SRC_OPTIMAL (unless GENERAL) and back to its layout inside the recording.
  void record_correlation(VkCommandBuffer cmd, std::span<const ImageFieldSource> members,
                          std::span<const float> reference_series, const CorrelationParams& params, Buffer& out);
  // Reads the ensemble in the compute-shader stage (beyond one texel view and from images also in
  // the transfer stage: transfer read) and writes `out` there (shader write; a transfer write when
  // the reference has NaN).
  static RecordedAccess access();

 private:
  Context& ctx_;
  std::unique_ptr<CorrelationKernel> kernel_;
  uint64_t max_chunk_voxels_;
  Buffer chunk_scratch_;  // the host's chunk memory, when lent
  CorrelationTables tables_;
  std::unique_ptr<CommandBatch> recording_;
  void record(VkCommandBuffer cmd, const DeviceEnsemble& ensemble, std::span<const float> reference_series,
              const CorrelationParams& params, Buffer& out);
};

// The RGBA voxel loss of a TF pair (voxel_loss_gpu), recorded; the result read after the wait.
class VoxelLossRecorder {
 public:
  explicit VoxelLossRecorder(Context& ctx);
  // The same in the host's scratch memory (RecorderScratch: the accumulators and the result,
  // scratch_bytes() each; the two TF tables, O(N), stay the recorder's). Throws
  // std::invalid_argument as NormalEquationsRecorder's does.
  VoxelLossRecorder(Context& ctx, const RecorderScratch& scratch);
  static uint64_t scratch_bytes();
  ~VoxelLossRecorder();
  VoxelLossRecorder(const VoxelLossRecorder&) = delete;
  VoxelLossRecorder& operator=(const VoxelLossRecorder&) = delete;

  // Records the tables, the loss pass (the same kernel and bits as voxel_loss_gpu) and the copy
  // of its O(1) sums to host-visible memory with the barrier to the host.
  void record_voxel_loss(VkCommandBuffer cmd, const DeviceField& ref, const DeviceField& opt,
                         const FieldMapping& ref_map, const FieldMapping& opt_map, std::span<const float> ref_tf_rgba,
                         std::span<const float> opt_tf_rgba);
  // The same from two of the host's 3D images read in place (ImageFieldView).
  void record_voxel_loss(VkCommandBuffer cmd, const ImageFieldView& ref, const ImageFieldView& opt,
                         const FieldMapping& ref_map, const FieldMapping& opt_map, std::span<const float> ref_tf_rgba,
                         std::span<const float> opt_tf_rgba);
  // After the host's wait for the submission; std::logic_error before any recording.
  VoxelLoss result() const;
  // Reads the fields in the compute-shader stage; writes only its own memory.
  static RecordedAccess access();

 private:
  Context& ctx_;
  std::unique_ptr<VoxelLossKernel> kernel_;
  Buffer ref_tf_, opt_tf_, accum_, result_;
  const void* result_mapped_ = nullptr;  // result_'s mapping: the recorder's or the host's
  std::unique_ptr<CommandBatch> recording_;
  bool recorded_ = false;
  template <class Field>
  void record_loss(VkCommandBuffer cmd, const Field& ref, const Field& opt, const FieldMapping& ref_map,
                   const FieldMapping& opt_map, std::span<const float> ref_tf_rgba, std::span<const float> opt_tf_rgba);
};

// Where record_tf_upload writes a TF table: a host's buffer (N RGBA float32 entries from
// `offset`), or row 0 of a host's 1D (or 2D) image of N texels in one of the formats below.
struct TfBufferTarget {
  VkBuffer buffer = VK_NULL_HANDLE;  // with VK_BUFFER_USAGE_TRANSFER_DST_BIT
  uint64_t offset = 0;               // a multiple of 4
  // Bytes of the host's range from `offset`, required (0: std::invalid_argument): the table must
  // fit it. Unchecked, a 128-byte table written into a 64-byte buffer corrupted the driver's heap.
  uint64_t size = 0;
};
struct TfImageTarget {
  VkImage image = VK_NULL_HANDLE;  // with VK_IMAGE_USAGE_TRANSFER_DST_BIT, width N, mip 0, layer 0 written
  VkFormat format = VK_FORMAT_R32G32B32A32_SFLOAT;  // or R16G16B16A16_SFLOAT, R8G8B8A8_UNORM
  VkImageLayout old_layout = VK_IMAGE_LAYOUT_UNDEFINED;                    // its layout before (contents dropped)
  VkImageLayout new_layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;     // its layout after
  VkPipelineStageFlags dst_stages = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;  // where the host reads it next
  VkAccessFlags dst_access = VK_ACCESS_SHADER_READ_BIT;
};

class TfUploadRecorder {
 public:
  explicit TfUploadRecorder(Context& ctx);
  ~TfUploadRecorder();
  TfUploadRecorder(const TfUploadRecorder&) = delete;
  TfUploadRecorder& operator=(const TfUploadRecorder&) = delete;

  // Records the write of `rgba` (N entries as 4N floats in [0, 1], e.g. Solution::rgba) into the
  // host's buffer, inside the command buffer (vkCmdUpdateBuffer: transfer stage, transfer write).
  // The host orders its reads after it (a barrier from VK_PIPELINE_STAGE_TRANSFER_BIT).
  void record_tf_upload(VkCommandBuffer cmd, std::span<const float> rgba, const TfBufferTarget& target);
  // Records the write into the host's image: the table converted to the image's format on the
  // host (float16 by glm::packHalf1x16; unorm8 round(255 x)), written into the recorder's staging
  // buffer inside the command buffer, copied to the image with the layout changes and the barrier
  // to `dst_stages`/`dst_access` recorded here. Keep the recorder until the host's wait returned.
  // Throws std::invalid_argument for another format or fewer than 2 entries.
  void record_tf_upload(VkCommandBuffer cmd, std::span<const float> rgba, const TfImageTarget& target);
  static RecordedAccess access();

 private:
  Context& ctx_;
  Buffer staging_;
  std::unique_ptr<CommandBatch> recording_;
};

// The bytes a TF table has in `format` (R32G32B32A32_SFLOAT, R16G16B16A16_SFLOAT, R8G8B8A8_UNORM),
// as record_tf_upload writes them: the CPU side of the conversion, for hosts and tests.
std::vector<uint8_t> encode_tf_texels(std::span<const float> rgba, VkFormat format);

}  // namespace tfm
