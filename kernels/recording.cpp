// Recording the assembly and the TF upload into a host's command buffers (kernels/recording.h).
#include "tfmatch/kernels/recording.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include <glm/gtc/packing.hpp>

#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/assemble_normal_equations.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/kernels/residual_map.h"
#include "tfmatch/kernels/voxel_loss.h"
#include "tfmatch/model/correlation_reference.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/shaders/shared_layout.h"

namespace tfm {

namespace {

// The recorder's batch, restarted on `cmd`: the last recording's descriptor pools are reused
// (creating pools each frame cost lavapipe more than the assembly of a small field).
CommandBatch& restart(std::unique_ptr<CommandBatch>& batch, Context& ctx, VkCommandBuffer cmd) {
  if (batch)
    batch->restart(cmd);
  else
    batch = std::make_unique<CommandBatch>(ctx, cmd);
  return *batch;
}

void check_tf_table(std::span<const float> rgba, const char* what) {
  if (rgba.size() % 4 || rgba.size() < 8)
    throw std::invalid_argument(std::string(what) + ": a TF table needs N >= 2 RGBA entries (4N floats), got " +
                                std::to_string(rgba.size()) + " floats");
}

// Throws std::invalid_argument unless `rgba` is a table of the size `map` reads.
void check_table_for(std::span<const float> rgba, const FieldMapping& map, const char* what) {
  check_tf_table(rgba, what);
  if (rgba.size() / 4 != map.tf_size)
    throw std::invalid_argument(std::string(what) + ": a TF has " + std::to_string(rgba.size() / 4) +
                                " entries, its mapping " + std::to_string(map.tf_size));
}

// Records the write of a TF table (checked by check_table_for) into `buffer`, grown when too small.
void record_table(CommandBatch& batch, Context& ctx, Buffer& buffer, std::span<const float> rgba, const char* what) {
  if (buffer.size() < rgba.size_bytes()) buffer = Buffer(ctx, rgba.size_bytes(), MemoryUsage::Device, what);
  batch.update(buffer, 0, rgba.data(), rgba.size_bytes());
}

// The host's scratch ranges of `bytes` each as the recorder's accumulators and result; returns
// the host's mapping of the result. Throws std::invalid_argument naming `who` for a missing
// mapping (and as Buffer::adopt does).
const void* adopt_scratch(Context& ctx, const RecorderScratch& scratch, uint64_t bytes, const char* who, Buffer& accum,
                          Buffer& result) {
  if (!scratch.result_mapped)
    throw std::invalid_argument(std::string(who) + ": the host's result range needs its mapping (result_mapped)");
  accum = Buffer::adopt(ctx, scratch.accumulators, scratch.accumulators_offset, bytes, "host scratch: accumulators");
  result = Buffer::adopt(ctx, scratch.result, scratch.result_offset, bytes, "host scratch: result");
  return scratch.result_mapped;
}

}  // namespace

NormalEquationsRecorder::NormalEquationsRecorder(Context& ctx, uint32_t tf_size, ReductionOptions options)
    : ctx_(ctx), kernel_(std::make_unique<AssembleNormalEquationsKernel>(ctx, tf_size, options)) {
  const uint64_t bytes = scratch_bytes(tf_size);
  accum_ = Buffer(ctx, bytes, MemoryUsage::Device, "recorded normal-equation accumulators");
  result_ = Buffer(ctx, bytes, MemoryUsage::Readback, "recorded normal-equation result");
  result_mapped_ = result_.mapped();
}

NormalEquationsRecorder::NormalEquationsRecorder(Context& ctx, uint32_t tf_size, const RecorderScratch& scratch,
                                                 ReductionOptions options)
    : ctx_(ctx), kernel_(std::make_unique<AssembleNormalEquationsKernel>(ctx, tf_size, options)) {
  result_mapped_ = adopt_scratch(ctx, scratch, scratch_bytes(tf_size), "NormalEquationsRecorder", accum_, result_);
}

uint64_t NormalEquationsRecorder::scratch_bytes(uint32_t tf_size) {
  check_table_size(tf_size);
  return uint64_t(TFM_ASSEMBLE_SLOTS(tf_size)) * gpu::kFixedSlotBytes;
}

NormalEquationsRecorder::~NormalEquationsRecorder() = default;

uint32_t NormalEquationsRecorder::tf_size() const { return kernel_->tf_size(); }

void NormalEquationsRecorder::record_assemble(VkCommandBuffer cmd, const DeviceField& ref, const DeviceField& opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              std::span<const float> ref_tf_rgba) {
  if (opt.voxel_count() != ref.voxel_count() || opt.chunk_voxels() != ref.chunk_voxels())
    throw std::invalid_argument("record_assemble: the fields differ in size or chunking");
  record_with(cmd, opt_map, ref_map, ref_tf_rgba,
              [&](CommandBatch& batch) { kernel_->record(batch, ref, opt, ref_map, opt_map, ref_tf_, accum_); });
}

void NormalEquationsRecorder::record_assemble(VkCommandBuffer cmd, const ImageFieldView& ref, const ImageFieldView& opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              std::span<const float> ref_tf_rgba) {
  check_image_pair(ref, opt, "record_assemble");  // before anything is recorded into the host's buffer
  record_with(cmd, opt_map, ref_map, ref_tf_rgba,
              [&](CommandBatch& batch) { kernel_->record(batch, ref, opt, ref_map, opt_map, ref_tf_, accum_); });
}

void NormalEquationsRecorder::record_with(VkCommandBuffer cmd, const FieldMapping& opt_map, const FieldMapping& ref_map,
                                          std::span<const float> ref_tf_rgba,
                                          const std::function<void(CommandBatch&)>& assemble) {
  check_table_for(ref_tf_rgba, ref_map, "record_assemble: reference TF");
  if (opt_map.tf_size != kernel_->tf_size())
    throw std::invalid_argument("record_assemble: the second field's mapping has " + std::to_string(opt_map.tf_size) +
                                " TF entries, the recorder " + std::to_string(kernel_->tf_size()));
  // The new recording replaces the last one's descriptor sets: the host waited for it (header).
  CommandBatch& batch = restart(recording_, ctx_, cmd);
  // Earlier uses of the recorder's memory (an earlier recording's copy of the result, its reads
  // of the table) finish before they are overwritten.
  batch.barrier();
  record_table(batch, ctx_, ref_tf_, ref_tf_rgba, "recorded reference TF");
  batch.fill(accum_, 0u);
  batch.barrier();
  assemble(batch);  // ends with a barrier
  batch.copy(accum_, 0, result_, 0, accum_.size());
  batch.barrier_to_host();
  recorded_ = true;
}

std::vector<uint32_t> NormalEquationsRecorder::result_words() const {
  if (!recorded_) throw std::logic_error("NormalEquationsRecorder::result: nothing recorded yet");
  std::vector<uint32_t> words(size_t(kernel_->slots()) * 2);
  std::memcpy(words.data(), result_mapped_, words.size() * sizeof(uint32_t));
  return words;
}

NormalEquations NormalEquationsRecorder::result() const {
  return NormalEquations::from_slots(kernel_->tf_size(), decode_fixed_point(result_words()), false);
}

std::vector<uint64_t> NormalEquationsRecorder::fixed_point_slots() const {
  const std::vector<uint32_t> words = result_words();
  std::vector<uint64_t> slots(words.size() / 2);
  for (size_t k = 0; k < slots.size(); ++k) slots[k] = uint64_t(words[2 * k]) | uint64_t(words[2 * k + 1]) << 32;
  return slots;
}

RecordedAccess NormalEquationsRecorder::access() {
  return {VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
          VK_ACCESS_SHADER_READ_BIT, 0};
}

ResidualMapRecorder::ResidualMapRecorder(Context& ctx)
    : ctx_(ctx), kernel_(std::make_unique<ResidualMapKernel>(ctx)) {}
ResidualMapRecorder::~ResidualMapRecorder() = default;

// Both TF tables and the map, the fields in buffers or images (ResidualMapKernel::record checks them).
template <class Field>
void record_residual(CommandBatch& batch, Context& ctx, ResidualMapKernel& kernel, Buffer& ref_tf, Buffer& opt_tf,
                     const Field& ref, const Field& opt, const FieldMapping& ref_map, const FieldMapping& opt_map,
                     std::span<const float> ref_tf_rgba, std::span<const float> opt_tf_rgba, DeviceField& out) {
  batch.barrier();  // earlier reads of the tables and writes of `out` finish first
  record_table(batch, ctx, ref_tf, ref_tf_rgba, "recorded reference TF");
  record_table(batch, ctx, opt_tf, opt_tf_rgba, "recorded second TF");
  batch.barrier();
  kernel.record(batch, ref, opt, ref_map, opt_map, ref_tf, opt_tf, out);
}

void ResidualMapRecorder::record_residual_map(VkCommandBuffer cmd, const DeviceField& ref, const DeviceField& opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              std::span<const float> ref_tf_rgba, std::span<const float> opt_tf_rgba,
                                              DeviceField& out) {
  check_table_for(ref_tf_rgba, ref_map, "record_residual_map: reference TF");
  check_table_for(opt_tf_rgba, opt_map, "record_residual_map: second TF");
  ResidualMapKernel::check_fields(ref, opt, out);  // before anything is recorded into the host's buffer
  record_residual(restart(recording_, ctx_, cmd), ctx_, *kernel_, ref_tf_, opt_tf_, ref, opt, ref_map, opt_map,
                  ref_tf_rgba, opt_tf_rgba, out);
}

void ResidualMapRecorder::record_residual_map(VkCommandBuffer cmd, const ImageFieldView& ref, const ImageFieldView& opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              std::span<const float> ref_tf_rgba, std::span<const float> opt_tf_rgba,
                                              DeviceField& out) {
  check_table_for(ref_tf_rgba, ref_map, "record_residual_map: reference TF");
  check_table_for(opt_tf_rgba, opt_map, "record_residual_map: second TF");
  ResidualMapKernel::check_fields(ref, opt, out);  // before anything is recorded into the host's buffer
  record_residual(restart(recording_, ctx_, cmd), ctx_, *kernel_, ref_tf_, opt_tf_, ref, opt, ref_map, opt_map,
                  ref_tf_rgba, opt_tf_rgba, out);
}

RecordedAccess ResidualMapRecorder::access() {
  return {VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_SHADER_READ_BIT,
          VK_ACCESS_SHADER_WRITE_BIT};
}

RenderRecorder::RenderRecorder(Context& ctx, const VolumeGeometry& geometry, uint32_t field_chunks)
    : ctx_(ctx), geometry_(geometry), kernel_(std::make_unique<RenderImageKernel>(ctx, field_chunks)) {
  views_ = Buffer(ctx, sizeof(gpu::RenderView), MemoryUsage::Device, "recorded render camera");
}
RenderRecorder::RenderRecorder(Context& ctx, const VolumeGeometry& geometry, uint32_t field_chunks,
                               VkBuffer stop_scratch, uint64_t offset, uint64_t bytes)
    : RenderRecorder(ctx, geometry, field_chunks) {
  if (bytes < 4) throw std::invalid_argument("RenderRecorder: the host's stop scratch holds no pixel");
  stop_ = Buffer::adopt(ctx, stop_scratch, offset, bytes, "host scratch: render stop indices");
  host_stop_ = true;
}

RenderRecorder::~RenderRecorder() = default;

void RenderRecorder::record_render(VkCommandBuffer cmd, const DeviceField& field, const FieldMapping& mapping,
                                   std::span<const float> tf_rgba, const RenderSettings& settings, Buffer& image) {
  record_picture(cmd, *kernel_, field, mapping, tf_rgba, settings, image);
}

void RenderRecorder::record_render(VkCommandBuffer cmd, const ImageFieldView& field, const FieldMapping& mapping,
                                   std::span<const float> tf_rgba, const RenderSettings& settings, Buffer& image) {
  // Checked before anything is recorded into the host's buffer.
  check_image_field(field, "record_render");
  if (field.extent.width != geometry_.dims[0] || field.extent.height != geometry_.dims[1] ||
      field.extent.depth != geometry_.dims[2])
    throw std::invalid_argument("record_render: the image's extent differs from the recorder's grid");
  if (!image_kernel_) image_kernel_ = std::make_unique<RenderImageKernel>(ctx_, RenderImageKernel::ImageField{});
  record_picture(cmd, *image_kernel_, field, mapping, tf_rgba, settings, image);
}

template <class Field>
void RenderRecorder::record_picture(VkCommandBuffer cmd, const RenderImageKernel& kernel, const Field& field,
                                    const FieldMapping& mapping, std::span<const float> tf_rgba,
                                    const RenderSettings& settings, Buffer& image) {
  check_table_for(tf_rgba, mapping, "record_render: TF");
  check_render_size(ctx_, settings);
  const uint64_t pixels = uint64_t(settings.width) * settings.height;
  if (image.size() < pixels * 16)
    throw std::invalid_argument("record_render: the image buffer holds " + std::to_string(image.size()) +
                                " bytes, a " + std::to_string(settings.width) + "x" + std::to_string(settings.height) +
                                " image needs " + std::to_string(pixels * 16));
  const MarchConstants march = march_constants(settings, geometry_);
  const gpu::RenderView view = make_render_view(orbit_frame(settings.camera, geometry_, settings.width, settings.height));
  const gpu::RenderPush push = make_render_push(geometry_, march, mapping, field, settings.width, settings.height, 1);
  kernel.check_field(field, push);  // before anything is recorded into the host's buffer
  if (stop_.size() < pixels * 4) {
    if (host_stop_)
      throw std::invalid_argument("record_render: the host's stop scratch holds " + std::to_string(stop_.size()) +
                                  " bytes, a " + std::to_string(settings.width) + "x" + std::to_string(settings.height) +
                                  " image needs " + std::to_string(pixels * 4));
    stop_ = Buffer(ctx_, pixels * 4, MemoryUsage::Device, "recorded render stop index");
  }
  CommandBatch& batch = restart(recording_, ctx_, cmd);
  batch.barrier();  // an earlier recording's reads of the table and camera finish first
  record_table(batch, ctx_, tf_, tf_rgba, "recorded render TF");
  batch.update(views_, 0, &view, sizeof view);
  batch.barrier();
  kernel.record(batch, field, tf_, views_, push, image, stop_, 0, settings.height);
}

RecordedAccess RenderRecorder::access() {
  return {VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_SHADER_READ_BIT,
          VK_ACCESS_SHADER_WRITE_BIT};
}

CorrelationRecorder::CorrelationRecorder(Context& ctx, uint64_t max_chunk_voxels)
    : ctx_(ctx), kernel_(std::make_unique<CorrelationKernel>(ctx)), max_chunk_voxels_(max_chunk_voxels) {}

CorrelationRecorder::CorrelationRecorder(Context& ctx, VkBuffer chunk_scratch, uint64_t offset, uint64_t bytes,
                                         uint64_t max_chunk_voxels)
    : CorrelationRecorder(ctx, max_chunk_voxels) {
  if (chunk_scratch == VK_NULL_HANDLE || bytes == 0)
    throw std::invalid_argument("CorrelationRecorder: no chunk scratch buffer or an empty range");
  if (offset % ctx.limits().minTexelBufferOffsetAlignment)
    throw std::invalid_argument("CorrelationRecorder: chunk scratch offset " + std::to_string(offset) +
                                " is not a multiple of the device's texel-buffer offset alignment " +
                                std::to_string(ctx.limits().minTexelBufferOffsetAlignment));
  chunk_scratch_ = Buffer::adopt(ctx, chunk_scratch, offset, bytes, "host correlation chunk");
}
CorrelationRecorder::~CorrelationRecorder() = default;

void CorrelationRecorder::record_correlation(VkCommandBuffer cmd, const Buffer& ensemble, uint64_t voxels,
                                             std::span<const float> reference_series, const CorrelationParams& params,
                                             Buffer& out) {
  record(cmd, DeviceEnsemble{&ensemble, voxels}, reference_series, params, out);
}

void CorrelationRecorder::record_correlation(VkCommandBuffer cmd, const Buffer& ensemble, FieldFormat format,
                                             uint64_t voxels, std::span<const float> reference_series,
                                             const CorrelationParams& params, Buffer& out) {
  DeviceEnsemble source{&ensemble, voxels};
  source.format = format;
  record(cmd, source, reference_series, params, out);
}

void CorrelationRecorder::record_correlation(VkCommandBuffer cmd, std::span<const ImageFieldSource> members,
                                             std::span<const float> reference_series, const CorrelationParams& params,
                                             Buffer& out) {
  if (members.empty()) throw std::invalid_argument("record_correlation: no member images");
  std::vector<CommandBatch::HostImage> images;
  for (const ImageFieldSource& m : members) {
    if (m.extent.width != members[0].extent.width || m.extent.height != members[0].extent.height ||
        m.extent.depth != members[0].extent.depth || m.format != members[0].format)
      throw std::invalid_argument("record_correlation: member image " + std::to_string(images.size()) +
                                  " differs from member 0 in extent or format");
    images.push_back({m.image, m.layout, m.src_stages, m.src_access, m.dst_stages, m.dst_access});
  }
  DeviceEnsemble source;
  source.images = images;
  source.extent = members[0].extent;
  source.format = field_format_of(members[0].format, "record_correlation");
  record(cmd, source, reference_series, params, out);
}

void CorrelationRecorder::record(VkCommandBuffer cmd, const DeviceEnsemble& ensemble,
                                 std::span<const float> reference_series, const CorrelationParams& params, Buffer& out) {
  const CorrelationReference ref = prepare_correlation_reference(reference_series, params);  // checks params
  kernel_->check_record(ensemble, params, ref.members, out);
  if (chunk_scratch_ && chunk_scratch_.size() < CorrelationKernel::min_chunk_bytes(ref.members, ensemble.format))
    throw std::invalid_argument("record_correlation: the host's chunk scratch holds " +
                                std::to_string(chunk_scratch_.size()) + " bytes; " + std::to_string(ref.members) +
                                " members of " + field_format_name(ensemble.format) + " need at least " +
                                std::to_string(CorrelationKernel::min_chunk_bytes(ref.members, ensemble.format)));
  CommandBatch& batch = restart(recording_, ctx_, cmd);
  batch.barrier();  // an earlier recording's reads of the tables and writes of `out` finish first
  record_correlation_tables(batch, ctx_, ref, tables_);
  batch.barrier();
  kernel_->record(batch, ensemble, ref, tables_, out, max_chunk_voxels_, chunk_scratch_ ? &chunk_scratch_ : nullptr);
}

RecordedAccess CorrelationRecorder::access() {
  return {VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
          VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT, VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT};
}

VoxelLossRecorder::VoxelLossRecorder(Context& ctx) : ctx_(ctx), kernel_(std::make_unique<VoxelLossKernel>(ctx)) {
  accum_ = Buffer(ctx, scratch_bytes(), MemoryUsage::Device, "recorded voxel-loss accumulators");
  result_ = Buffer(ctx, scratch_bytes(), MemoryUsage::Readback, "recorded voxel-loss result");
  result_mapped_ = result_.mapped();
}

VoxelLossRecorder::VoxelLossRecorder(Context& ctx, const RecorderScratch& scratch)
    : ctx_(ctx), kernel_(std::make_unique<VoxelLossKernel>(ctx)) {
  result_mapped_ = adopt_scratch(ctx, scratch, scratch_bytes(), "VoxelLossRecorder", accum_, result_);
}

uint64_t VoxelLossRecorder::scratch_bytes() { return TFM_LOSS_SLOTS * gpu::kFixedSlotBytes; }
VoxelLossRecorder::~VoxelLossRecorder() = default;

void VoxelLossRecorder::record_voxel_loss(VkCommandBuffer cmd, const DeviceField& ref, const DeviceField& opt,
                                          const FieldMapping& ref_map, const FieldMapping& opt_map,
                                          std::span<const float> ref_tf_rgba, std::span<const float> opt_tf_rgba) {
  if (opt.voxel_count() != ref.voxel_count() || opt.chunk_voxels() != ref.chunk_voxels())
    throw std::invalid_argument("record_voxel_loss: the fields differ in size or chunking");
  record_loss(cmd, ref, opt, ref_map, opt_map, ref_tf_rgba, opt_tf_rgba);
}

void VoxelLossRecorder::record_voxel_loss(VkCommandBuffer cmd, const ImageFieldView& ref, const ImageFieldView& opt,
                                          const FieldMapping& ref_map, const FieldMapping& opt_map,
                                          std::span<const float> ref_tf_rgba, std::span<const float> opt_tf_rgba) {
  check_image_pair(ref, opt, "record_voxel_loss");  // before anything is recorded into the host's buffer
  record_loss(cmd, ref, opt, ref_map, opt_map, ref_tf_rgba, opt_tf_rgba);
}

template <class Field>
void VoxelLossRecorder::record_loss(VkCommandBuffer cmd, const Field& ref, const Field& opt, const FieldMapping& ref_map,
                                    const FieldMapping& opt_map, std::span<const float> ref_tf_rgba,
                                    std::span<const float> opt_tf_rgba) {
  check_table_for(ref_tf_rgba, ref_map, "record_voxel_loss: reference TF");
  check_table_for(opt_tf_rgba, opt_map, "record_voxel_loss: second TF");
  CommandBatch& batch = restart(recording_, ctx_, cmd);
  batch.barrier();
  record_table(batch, ctx_, ref_tf_, ref_tf_rgba, "recorded reference TF");
  record_table(batch, ctx_, opt_tf_, opt_tf_rgba, "recorded second TF");
  batch.fill(accum_, 0u);
  batch.barrier();
  kernel_->record(batch, ref, opt, ref_map, opt_map, ref_tf_, opt_tf_, accum_);
  batch.barrier();
  batch.copy(accum_, 0, result_, 0, accum_.size());
  batch.barrier_to_host();
  recorded_ = true;
}

VoxelLoss VoxelLossRecorder::result() const {
  if (!recorded_) throw std::logic_error("VoxelLossRecorder::result: nothing recorded yet");
  std::vector<uint32_t> words(TFM_LOSS_SLOTS * TFM_FIXED_SLOT_WORDS);
  std::memcpy(words.data(), result_mapped_, words.size() * sizeof(uint32_t));
  return decode_voxel_losses(words)[0];
}

RecordedAccess VoxelLossRecorder::access() {
  return {VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_SHADER_READ_BIT, 0};
}

std::vector<uint8_t> encode_tf_texels(std::span<const float> rgba, VkFormat format) {
  check_tf_table(rgba, "encode_tf_texels");
  std::vector<uint8_t> out;
  switch (format) {
    case VK_FORMAT_R32G32B32A32_SFLOAT:
      out.resize(rgba.size_bytes());
      std::memcpy(out.data(), rgba.data(), out.size());
      break;
    case VK_FORMAT_R16G16B16A16_SFLOAT:
      out.resize(rgba.size() * 2);
      for (size_t i = 0; i < rgba.size(); ++i) {
        const uint16_t h = glm::packHalf1x16(rgba[i]);
        std::memcpy(out.data() + 2 * i, &h, 2);
      }
      break;
    case VK_FORMAT_R8G8B8A8_UNORM:
      out.resize(rgba.size());
      for (size_t i = 0; i < rgba.size(); ++i)
        out[i] = uint8_t(std::lround(std::clamp(rgba[i], 0.0f, 1.0f) * 255.0f));
      break;
    default:
      throw std::invalid_argument("record_tf_upload: TF image format " + vk_format_name(format) +
                                  " (supported: R32G32B32A32_SFLOAT, R16G16B16A16_SFLOAT, R8G8B8A8_UNORM)");
  }
  return out;
}

TfUploadRecorder::TfUploadRecorder(Context& ctx) : ctx_(ctx) {}
TfUploadRecorder::~TfUploadRecorder() = default;

void TfUploadRecorder::record_tf_upload(VkCommandBuffer cmd, std::span<const float> rgba, const TfBufferTarget& target) {
  check_tf_table(rgba, "record_tf_upload");
  const uint64_t bytes = rgba.size_bytes();
  if (target.size == 0 || target.size == VK_WHOLE_SIZE)
    throw std::invalid_argument("record_tf_upload: TfBufferTarget::size: give the bytes of the host's range (the "
                                "table needs " + std::to_string(bytes) + ")");
  if (target.size < bytes)
    throw std::invalid_argument("record_tf_upload: the table needs " + std::to_string(bytes) +
                                " bytes, the target range holds " + std::to_string(target.size));
  if (target.offset % 4) throw std::invalid_argument("record_tf_upload: the target offset is not a multiple of 4");
  // A view of the host's buffer from its start (always aligned) to the table's end: an update
  // needs no alignment beyond 4, which update() checks.
  const Buffer dst = Buffer::adopt(ctx_, target.buffer, 0, target.offset + bytes, "record_tf_upload target");
  restart(recording_, ctx_, cmd).update(dst, target.offset, rgba.data(), bytes);
}

void TfUploadRecorder::record_tf_upload(VkCommandBuffer cmd, std::span<const float> rgba, const TfImageTarget& target) {
  if (target.image == VK_NULL_HANDLE) throw std::invalid_argument("record_tf_upload: no image (VK_NULL_HANDLE)");
  std::vector<uint8_t> texels = encode_tf_texels(rgba, target.format);
  texels.resize((texels.size() + 3) / 4 * 4, 0);  // update() writes whole words
  const uint64_t bytes = texels.size();
  if (staging_.size() < bytes) staging_ = Buffer(ctx_, bytes, MemoryUsage::Device, "recorded TF staging");
  CommandBatch& batch = restart(recording_, ctx_, cmd);
  batch.barrier();  // an earlier copy out of the staging buffer finishes first
  batch.update(staging_, 0, texels.data(), bytes);
  batch.copy_to_image(staging_, target.image, uint32_t(rgba.size() / 4), target.old_layout, target.new_layout,
                      target.dst_stages, target.dst_access);
}

namespace {

uint64_t extent_voxels(VkExtent3D extent, const std::string& name) {
  const uint64_t voxels = uint64_t(extent.width) * extent.height * extent.depth;
  if (voxels == 0)
    throw std::invalid_argument("ImageFieldRecorder '" + name + "': empty extent " + std::to_string(extent.width) + "x" +
                                std::to_string(extent.height) + "x" + std::to_string(extent.depth));
  return voxels;
}

}  // namespace

uint64_t ImageFieldRecorder::bytes_needed(VkExtent3D extent, VkFormat format) {
  return uint64_t(extent.width) * extent.height * extent.depth *
         field_format_bytes(field_format_of(format, "ImageFieldRecorder"));
}

ImageFieldRecorder::ImageFieldRecorder(Context& ctx, VkExtent3D extent, VkFormat format, const std::string& name,
                                       uint64_t max_chunk_voxels)
    : ctx_(ctx),
      extent_(extent),
      format_(field_format_of(format, "ImageFieldRecorder")),
      own_(ctx, std::max<uint64_t>(4, (extent_voxels(extent, name) * field_format_bytes(format_) + 3) / 4 * 4),
           MemoryUsage::Device, name + " (copy of the host's image)"),
      field_(DeviceField::adopt(ctx, own_.handle(), own_.offset(), extent_voxels(extent, name), name, max_chunk_voxels,
                                format_)) {}

ImageFieldRecorder::ImageFieldRecorder(Context& ctx, VkExtent3D extent, VkFormat format, const std::string& name,
                                       VkBuffer buffer, uint64_t offset, uint64_t max_chunk_voxels)
    : ctx_(ctx),
      extent_(extent),
      format_(field_format_of(format, "ImageFieldRecorder")),
      field_(DeviceField::adopt(ctx, buffer, offset, extent_voxels(extent, name), name, max_chunk_voxels, format_)) {}

ImageFieldRecorder::~ImageFieldRecorder() = default;

void ImageFieldRecorder::record_copy(VkCommandBuffer cmd, const ImageFieldSource& source) {
  if (source.image == VK_NULL_HANDLE) throw std::invalid_argument("record_copy: no image (VK_NULL_HANDLE)");
  if (field_format_of(source.format, "record_copy") != format_ || source.extent.width != extent_.width ||
      source.extent.height != extent_.height || source.extent.depth != extent_.depth)
    throw std::invalid_argument("record_copy: the image is " + std::to_string(source.extent.width) + "x" +
                                std::to_string(source.extent.height) + "x" + std::to_string(source.extent.depth) + " " +
                                field_format_name(field_format_of(source.format, "record_copy")) +
                                ", the recorder's field " + std::to_string(extent_.width) + "x" +
                                std::to_string(extent_.height) + "x" + std::to_string(extent_.depth) + " " +
                                field_format_name(format_));
  CommandBatch& batch = restart(recording_, ctx_, cmd);
  // The chunks are views of one range of one buffer: the copy writes it from the first chunk's start.
  const Buffer& first = field_.chunk(0);
  batch.copy_from_image(source.image, source.extent, source.layout, source.src_stages, source.src_access,
                        source.dst_stages, source.dst_access, first, 0);
}

RecordedAccess ImageFieldRecorder::access() {
  return {VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT, 0};
}

RecordedAccess TfUploadRecorder::access() {
  return {VK_PIPELINE_STAGE_TRANSFER_BIT, 0, VK_ACCESS_TRANSFER_WRITE_BIT};
}

}  // namespace tfm
