// Command batches: one command buffer, fence, descriptor pools and timestamp queries each.
#include "tfmatch/engine/commands.h"

#include <algorithm>
#include <stdexcept>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"  // vk_format_name
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/engine/vk_check.h"
#include "tfmatch/engine/vk_dispatch.h"
#include "tfmatch/model/phase_timer.h"

namespace tfm {
namespace {
constexpr uint32_t kMaxTimestamps = 128;
constexpr uint32_t kSetsPerPool = 64;
constexpr uint32_t kDescriptorsPerPool = 1024;
}  // namespace

Binding::Binding(const Buffer& b) : buffers{&b} {}
Binding::Binding(std::vector<const Buffer*> array) : buffers(std::move(array)) {}

Binding Binding::image(VkImageView view, VkImageLayout layout) {
  Binding b(std::vector<const Buffer*>{});
  b.image_view = view;
  b.image_layout = layout;
  return b;
}

Binding Binding::texels(const Buffer& b, VkFormat format, uint64_t offset, uint64_t range) {
  Binding binding(b);
  binding.texel_format = format;
  binding.texel_offset = offset;
  binding.texel_range = range;
  return binding;
}

Binding Binding::texels(std::vector<const Buffer*> array, VkFormat format) {
  Binding binding(std::move(array));
  binding.texel_format = format;
  return binding;
}

static uint32_t texel_bytes(VkFormat format) {
  switch (format) {
    case VK_FORMAT_R8_UNORM: return 1;
    case VK_FORMAT_R16_SFLOAT:
    case VK_FORMAT_R16_UNORM: return 2;
    case VK_FORMAT_R8G8B8A8_UNORM:
    case VK_FORMAT_R32_SFLOAT:
    case VK_FORMAT_R32_UINT: return 4;
    case VK_FORMAT_R16G16B16A16_SFLOAT:
    case VK_FORMAT_R16G16B16A16_UNORM:
    case VK_FORMAT_R32G32_SFLOAT:
    case VK_FORMAT_R32G32_UINT: return 8;
    case VK_FORMAT_R32G32B32A32_SFLOAT:
    case VK_FORMAT_R32G32B32A32_UINT: return 16;
    default: throw std::logic_error("texel binding: unsupported format " + vk_format_name(format));
  }
}

CommandBatch::CommandBatch(Context& ctx) : ctx_(ctx) {
  const auto& vk = ctx.vk();
  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_TRANSIENT_BIT;
  pool_info.queueFamilyIndex = ctx.queue_family();
  VK_CHECK(vk.vkCreateCommandPool(ctx.device(), &pool_info, nullptr, &pool_));
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = pool_;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  VK_CHECK(vk.vkAllocateCommandBuffers(ctx.device(), &alloc, &cmd_));
  VkFenceCreateInfo fence_info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VK_CHECK(vk.vkCreateFence(ctx.device(), &fence_info, nullptr, &fence_));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  VK_CHECK(vk.vkBeginCommandBuffer(cmd_, &begin));
  if (ctx.timestamps_supported()) {
    VkQueryPoolCreateInfo q{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    q.queryType = VK_QUERY_TYPE_TIMESTAMP;
    q.queryCount = kMaxTimestamps;
    VK_CHECK(vk.vkCreateQueryPool(ctx.device(), &q, nullptr, &queries_));
    vk.vkCmdResetQueryPool(cmd_, queries_, 0, kMaxTimestamps);
  }
}

CommandBatch::CommandBatch(Context& ctx, VkCommandBuffer cmd) : ctx_(ctx), cmd_(cmd), external_(true) {
  if (cmd == VK_NULL_HANDLE) throw std::invalid_argument("CommandBatch: no command buffer to record into");
}

void CommandBatch::restart(VkCommandBuffer cmd) {
  if (!external_) throw std::logic_error("CommandBatch::restart: only a batch recording into a host's command buffer");
  if (cmd == VK_NULL_HANDLE) throw std::invalid_argument("CommandBatch: no command buffer to record into");
  const auto& vk = ctx_.vk();
  for (auto v : buffer_views_) vk.vkDestroyBufferView(ctx_.device(), v, nullptr);
  buffer_views_.clear();
  // The pools are kept, reset: allocate_set fills them in order before it makes another.
  for (auto p : descriptor_pools_) VK_CHECK(vk.vkResetDescriptorPool(ctx_.device(), p, 0));
  current_pool_ = 0;
  cmd_ = cmd;
}

CommandBatch::~CommandBatch() {
  const auto& vk = ctx_.vk();
  // A batch recorded but never submitted, or destroyed by an exception mid-wait, must not be
  // freed while the device may still use it.
  if (submitted_ && !waited_) {
    PhaseScope timing(Phase::Compute, PhaseScope::Nesting::YieldToOuter);
    vk.vkWaitForFences(ctx_.device(), 1, &fence_, VK_TRUE, UINT64_MAX);
  }
  if (queries_) vk.vkDestroyQueryPool(ctx_.device(), queries_, nullptr);
  for (auto p : descriptor_pools_) vk.vkDestroyDescriptorPool(ctx_.device(), p, nullptr);
  for (auto v : buffer_views_) vk.vkDestroyBufferView(ctx_.device(), v, nullptr);
  if (external_) return;  // the command buffer is the host's
  vk.vkDestroyFence(ctx_.device(), fence_, nullptr);
  vk.vkDestroyCommandPool(ctx_.device(), pool_, nullptr);
}

VkDescriptorSet CommandBatch::allocate_set(VkDescriptorSetLayout layout) {
  const auto& vk = ctx_.vk();
  VkDescriptorSetAllocateInfo alloc{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  alloc.descriptorSetCount = 1;
  alloc.pSetLayouts = &layout;
  VkDescriptorSet set = VK_NULL_HANDLE;
  for (; current_pool_ < descriptor_pools_.size(); ++current_pool_) {
    alloc.descriptorPool = descriptor_pools_[current_pool_];
    VkResult r = vk.vkAllocateDescriptorSets(ctx_.device(), &alloc, &set);
    if (r == VK_SUCCESS) return set;
    if (r != VK_ERROR_OUT_OF_POOL_MEMORY && r != VK_ERROR_FRAGMENTED_POOL)
      throw_vk_error("vkAllocateDescriptorSets", r, __FILE__, __LINE__);
  }
  const VkDescriptorPoolSize sizes[] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, kDescriptorsPerPool},
                                       {VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, kDescriptorsPerPool},
                                       {VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE, kDescriptorsPerPool}};
  VkDescriptorPoolCreateInfo info{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  info.maxSets = kSetsPerPool;
  info.poolSizeCount = static_cast<uint32_t>(std::size(sizes));
  info.pPoolSizes = sizes;
  VkDescriptorPool pool = VK_NULL_HANDLE;
  VK_CHECK(vk.vkCreateDescriptorPool(ctx_.device(), &info, nullptr, &pool));
  descriptor_pools_.push_back(pool);
  alloc.descriptorPool = pool;
  VK_CHECK(vk.vkAllocateDescriptorSets(ctx_.device(), &alloc, &set));
  return set;
}

void CommandBatch::dispatch(const ComputePipeline& pipeline, std::span<const Binding> bindings,
                            const void* push, uint32_t push_bytes, Groups groups) {
  const PipelineDesc& desc = pipeline.desc();
  if (bindings.size() != desc.binding_counts.size())
    throw std::logic_error(desc.shader + ": " + std::to_string(bindings.size()) + " bindings given, " +
                           std::to_string(desc.binding_counts.size()) + " expected");
  if (push_bytes != desc.push_constant_bytes)
    throw std::logic_error(desc.shader + ": push constants of " + std::to_string(push_bytes) +
                           " bytes given, " + std::to_string(desc.push_constant_bytes) + " expected");
  const auto& limits = ctx_.limits();
  if (groups.x == 0 || groups.y == 0 || groups.z == 0) return;  // nothing to do
  if (groups.x > limits.maxComputeWorkGroupCount[0] || groups.y > limits.maxComputeWorkGroupCount[1] ||
      groups.z > limits.maxComputeWorkGroupCount[2])
    throw std::runtime_error(desc.shader + ": group count exceeds the device's maxComputeWorkGroupCount");

  const auto& vk = ctx_.vk();
  VkDescriptorSet set = allocate_set(pipeline.set_layout());
  std::vector<std::vector<VkDescriptorBufferInfo>> infos;
  std::vector<std::vector<VkBufferView>> views;
  std::vector<VkDescriptorImageInfo> images;
  std::vector<VkWriteDescriptorSet> writes;
  infos.reserve(bindings.size());
  views.reserve(bindings.size());
  images.reserve(bindings.size());
  uint32_t index = 0;
  for (const Binding& b : bindings) {
    const std::string where = desc.shader + ": binding " + std::to_string(index);
    const bool image = pipeline.binding_kind(index) == DescriptorKind::SampledImage;
    if (image != (b.image_view != VK_NULL_HANDLE))
      throw std::logic_error(where + (image ? " is a sampled image: bind it with Binding::image" : " is not an image"));
    if (image) {
      if (desc.binding_counts[index] != 1) throw std::logic_error(where + ": image arrays are not supported");
      images.push_back({VK_NULL_HANDLE, b.image_view, b.image_layout});
      VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
      w.dstSet = set;
      w.dstBinding = index;
      w.descriptorType = VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE;
      w.descriptorCount = 1;
      w.pImageInfo = &images.back();
      writes.push_back(w);
      ++index;
      continue;
    }
    if (b.buffers.size() != desc.binding_counts[index])
      throw std::logic_error(where + " needs " + std::to_string(desc.binding_counts[index]) + " buffers");
    for (const Buffer* buf : b.buffers)
      if (!buf || !*buf) throw std::logic_error(where + " is empty");
    const bool texel = pipeline.binding_kind(index) == DescriptorKind::UniformTexelBuffer;
    if (texel != (b.texel_format != VK_FORMAT_UNDEFINED))
      throw std::logic_error(where + (texel ? " is a texel buffer: bind it with Binding::texels"
                                            : " is a storage buffer, given as texels"));
    VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    w.dstSet = set;
    w.dstBinding = index;
    w.descriptorType = descriptor_type(pipeline.binding_kind(index));
    if (texel) {
      if (b.buffers.size() > 1 && (b.texel_offset != 0 || b.texel_range != VK_WHOLE_SIZE))
        throw std::logic_error(where + ": an array of texel buffers takes whole buffers");
      // Every kernel's field formats are checked where the field enters (require_field_format);
      // this catches any texel format a kernel binds that the device cannot read.
      if (!(ctx_.buffer_format_features(b.texel_format) & VK_FORMAT_FEATURE_UNIFORM_TEXEL_BUFFER_BIT))
        throw UnsupportedFieldFormat(where + ": " + ctx_.device_name() + " reads no uniform texel buffer of " +
                                     vk_format_name(b.texel_format));
      auto& list = views.emplace_back();
      for (const Buffer* buf : b.buffers) {
        const uint64_t texel = texel_bytes(b.texel_format);
        const uint64_t range = b.texel_range == VK_WHOLE_SIZE ? (buf->size() - b.texel_offset) / texel * texel
                                                              : b.texel_range;
        if (b.texel_offset % limits.minTexelBufferOffsetAlignment || b.texel_offset + range > buf->size() ||
            range % texel || range == 0)
          throw std::logic_error(where + ": texel range [" + std::to_string(b.texel_offset) + ", +" +
                                 std::to_string(range) + ") misaligned or outside the buffer");
        if (range / texel > limits.maxTexelBufferElements)
          throw std::logic_error(where + ": " + std::to_string(range / texel) + " texels exceed the device's " +
                                 std::to_string(limits.maxTexelBufferElements));
        VkBufferViewCreateInfo vi{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
        vi.buffer = buf->handle();
        vi.format = b.texel_format;
        vi.offset = buf->offset() + b.texel_offset;
        vi.range = range;
        VkBufferView view = VK_NULL_HANDLE;
        VK_CHECK(vk.vkCreateBufferView(ctx_.device(), &vi, nullptr, &view));
        buffer_views_.push_back(view);
        list.push_back(view);
      }
      w.descriptorCount = static_cast<uint32_t>(list.size());
      w.pTexelBufferView = list.data();
    } else {
      auto& list = infos.emplace_back();
      for (const Buffer* buf : b.buffers) list.push_back({buf->handle(), buf->offset(), buf->size()});
      w.descriptorCount = static_cast<uint32_t>(list.size());
      w.pBufferInfo = list.data();
    }
    writes.push_back(w);
    ++index;
  }
  vk.vkUpdateDescriptorSets(ctx_.device(), static_cast<uint32_t>(writes.size()), writes.data(), 0, nullptr);
  vk.vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.pipeline());
  vk.vkCmdBindDescriptorSets(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.layout(), 0, 1, &set, 0, nullptr);
  if (push_bytes)
    vk.vkCmdPushConstants(cmd_, pipeline.layout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, push_bytes, push);
  vk.vkCmdDispatch(cmd_, groups.x, groups.y, groups.z);
}

void CommandBatch::barrier() {
  VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_READ_BIT |
                    VK_ACCESS_TRANSFER_WRITE_BIT;
  VkPipelineStageFlags stages = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT;
  ctx_.vk().vkCmdPipelineBarrier(cmd_, stages, stages, 0, 1, &b, 0, nullptr, 0, nullptr);
}

void CommandBatch::barrier_to_host() {
  VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  ctx_.vk().vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                                 VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &b, 0, nullptr, 0, nullptr);
}

void CommandBatch::copy(const Buffer& src, uint64_t src_offset, const Buffer& dst, uint64_t dst_offset,
                        uint64_t bytes) {
  VkBufferCopy region{src.offset() + src_offset, dst.offset() + dst_offset, bytes};
  ctx_.vk().vkCmdCopyBuffer(cmd_, src.handle(), dst.handle(), 1, &region);
}

void CommandBatch::fill(Buffer& dst, uint32_t value) {
  ctx_.vk().vkCmdFillBuffer(cmd_, dst.handle(), dst.offset(), dst.adopted() ? dst.size() / 4 * 4 : VK_WHOLE_SIZE, value);
}

void CommandBatch::update(const Buffer& dst, uint64_t offset, const void* data, uint64_t bytes) {
  constexpr uint64_t kPiece = 65536;  // vkCmdUpdateBuffer's limit per call
  if (offset % 4 || bytes % 4 || offset + bytes > dst.size())
    throw std::logic_error("CommandBatch::update: range [" + std::to_string(offset) + ", +" + std::to_string(bytes) +
                           ") misaligned or outside the buffer");
  const auto* bytes_in = static_cast<const uint8_t*>(data);
  for (uint64_t done = 0; done < bytes; done += kPiece)
    ctx_.vk().vkCmdUpdateBuffer(cmd_, dst.handle(), dst.offset() + offset + done, std::min(kPiece, bytes - done),
                                bytes_in + done);
}

namespace {
// The layout a host's image is copied from: its own when a copy may read it there.
VkImageLayout copy_layout_of(VkImageLayout layout) {
  return layout == VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL || layout == VK_IMAGE_LAYOUT_GENERAL
             ? layout
             : VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
}

VkImageMemoryBarrier whole_image_barrier(VkImage image, VkImageLayout from, VkImageLayout to, VkAccessFlags src,
                                         VkAccessFlags dst) {
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.srcAccessMask = src;
  b.dstAccessMask = dst;
  b.oldLayout = from;
  b.newLayout = to;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image;
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  return b;
}
}  // namespace

void CommandBatch::copy_to_image(const Buffer& src, VkImage image, uint32_t width, VkImageLayout old_layout,
                                 VkImageLayout new_layout, VkPipelineStageFlags dst_stages, VkAccessFlags dst_access) {
  const auto& vk = ctx_.vk();
  VkMemoryBarrier staged{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  staged.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  staged.dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  // The old contents are overwritten: only the layout change waits.
  const VkImageMemoryBarrier to_dst = whole_image_barrier(image, old_layout, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0,
                                                          VK_ACCESS_TRANSFER_WRITE_BIT);
  // The host's earlier reads of the image (any stage) finish before the layout changes.
  vk.vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_ALL_COMMANDS_BIT,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &staged, 0, nullptr, 1, &to_dst);
  VkBufferImageCopy region{};
  region.bufferOffset = src.offset();
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {width, 1, 1};
  vk.vkCmdCopyBufferToImage(cmd_, src.handle(), image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
  const VkImageMemoryBarrier to_use = whole_image_barrier(image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, new_layout,
                                                          VK_ACCESS_TRANSFER_WRITE_BIT, dst_access);
  vk.vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT, dst_stages, 0, 0, nullptr, 0, nullptr, 1, &to_use);
}


void CommandBatch::begin_image_copies(std::span<const HostImage> images) {
  VkPipelineStageFlags host_before = 0;
  std::vector<VkImageMemoryBarrier> barriers;
  for (const HostImage& im : images) {
    host_before |= im.src_stages;
    barriers.push_back(whole_image_barrier(im.image, im.layout, copy_layout_of(im.layout), im.src_access,
                                           VK_ACCESS_TRANSFER_READ_BIT));
  }
  // Earlier reads and writes of the copies' destinations (the kernels that read the last copy,
  // the last copy) finish before the copies write them.
  VkMemoryBarrier before{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  before.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_SHADER_WRITE_BIT;
  before.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  ctx_.vk().vkCmdPipelineBarrier(
      cmd_, (host_before ? host_before : VkPipelineStageFlags(VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT)) | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT |
                VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &before, 0, nullptr, static_cast<uint32_t>(barriers.size()),
      barriers.data());
}

void CommandBatch::copy_image_voxels(const HostImage& image, VkExtent3D extent, uint32_t texel_bytes, uint64_t first,
                                     uint64_t count, const Buffer& dst, uint64_t dst_offset) {
  const uint64_t nx = extent.width, ny = extent.height, slice = nx * ny;
  if (count == 0) return;
  if (first + count > slice * extent.depth)
    throw std::logic_error("copy_image_voxels: voxels [" + std::to_string(first) + ", +" + std::to_string(count) +
                           ") outside the image");
  std::vector<VkBufferImageCopy> regions;
  uint64_t v = first;
  const uint64_t end = first + count;
  // One box of whole texels starting at voxel v: `w` texels of a row, `h` rows, `d` slices.
  auto add = [&](uint64_t w, uint64_t h, uint64_t d) {
    VkBufferImageCopy r{};
    r.bufferOffset = dst.offset() + dst_offset + (v - first) * texel_bytes;
    r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    r.imageOffset = {int32_t(v % nx), int32_t(v / nx % ny), int32_t(v / slice)};
    r.imageExtent = {uint32_t(w), uint32_t(h), uint32_t(d)};
    regions.push_back(r);
    v += w * h * d;
  };
  if (v % nx) add(std::min(nx - v % nx, end - v), 1, 1);  // the rest of the first row
  if (v < end && v % slice) {                               // whole rows to the end of the slice
    const uint64_t rows = std::min(ny - v / nx % ny, (end - v) / nx);
    if (rows) add(nx, rows, 1);
  }
  if (v < end && (end - v) / slice) add(nx, ny, (end - v) / slice);  // whole slices
  if (v < end && (end - v) / nx) add(nx, (end - v) / nx, 1);         // whole rows of the last slice
  if (v < end) add(end - v, 1, 1);                                   // the start of the last row
  ctx_.vk().vkCmdCopyImageToBuffer(cmd_, image.image, copy_layout_of(image.layout), dst.handle(),
                                   static_cast<uint32_t>(regions.size()), regions.data());
}

void CommandBatch::end_image_copies(std::span<const HostImage> images) {
  VkPipelineStageFlags host_after = 0;
  std::vector<VkImageMemoryBarrier> barriers;
  for (const HostImage& im : images) {
    host_after |= im.dst_stages;
    if (copy_layout_of(im.layout) != im.layout)  // the copies only read it: nothing to make visible
      barriers.push_back(whole_image_barrier(im.image, copy_layout_of(im.layout), im.layout, 0, im.dst_access));
  }
  // The copies are visible to the kernels that read them; the images go back to the host's
  // layouts before its next use of them.
  VkMemoryBarrier after{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  after.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  after.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
  ctx_.vk().vkCmdPipelineBarrier(
      cmd_, VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | (host_after ? host_after : VkPipelineStageFlags(VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT)), 0, 1,
      &after, 0, nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
}

void CommandBatch::copy_from_image(VkImage image, VkExtent3D extent, VkImageLayout layout,
                                   VkPipelineStageFlags src_stages, VkAccessFlags src_access,
                                   VkPipelineStageFlags dst_stages, VkAccessFlags dst_access, const Buffer& dst,
                                   uint64_t dst_offset) {
  const HostImage host{image, layout, src_stages, src_access, dst_stages, dst_access};
  begin_image_copies({&host, 1});
  VkBufferImageCopy region{};
  region.bufferOffset = dst.offset() + dst_offset;
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = extent;
  ctx_.vk().vkCmdCopyImageToBuffer(cmd_, image, copy_layout_of(layout), dst.handle(), 1, &region);
  end_image_copies({&host, 1});
}

uint32_t CommandBatch::timestamp() {
  if (external_) throw std::logic_error("CommandBatch: no timestamps in a host's command buffer");
  // Past the pool's slots a timestamp is not written, as on a device without timestamps: its
  // slot's times are -1 (a long DiffDVR batch of thousands of views asks for more).
  if (!queries_ || query_count_ >= kMaxTimestamps) return query_count_++;
  ctx_.vk().vkCmdWriteTimestamp(cmd_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_, query_count_);
  return query_count_++;
}

void CommandBatch::submit_and_wait() {
  submit();
  wait();
}

void CommandBatch::submit() {
  if (external_) throw std::logic_error("CommandBatch: a host's command buffer is the host's to submit");
  if (submitted_) throw std::logic_error("CommandBatch submitted twice");
  const auto& vk = ctx_.vk();
  // Make every device write available to the host before the fence signals.
  barrier_to_host();
  VK_CHECK(vk.vkEndCommandBuffer(cmd_));
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cmd_;
  {
    std::lock_guard lock(ctx_.queue_mutex());
    VK_CHECK(vk.vkQueueSubmit(ctx_.queue(), 1, &submit, fence_));
  }
  ctx_.count_submission();
  submitted_ = true;
}

void CommandBatch::wait() {
  if (external_) throw std::logic_error("CommandBatch: the host waits for its own command buffer");
  if (!submitted_) throw std::logic_error("CommandBatch waited for before it was submitted");
  if (waited_) return;
  // Device work waited for inside an upload or a readback counts as that transfer.
  PhaseScope timing(Phase::Compute, PhaseScope::Nesting::YieldToOuter);
  const auto& vk = ctx_.vk();
  VK_CHECK(vk.vkWaitForFences(ctx_.device(), 1, &fence_, VK_TRUE, UINT64_MAX));
  waited_ = true;
  if (queries_ && query_count_ > 0) {
    query_results_.resize(std::min(query_count_, kMaxTimestamps));
    VK_CHECK(vk.vkGetQueryPoolResults(ctx_.device(), queries_, 0, uint32_t(query_results_.size()),
                                      query_results_.size() * sizeof(uint64_t), query_results_.data(),
                                      sizeof(uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
  }
}

double CommandBatch::elapsed_ms(uint32_t a, uint32_t b) const {
  if (query_results_.empty() || a >= query_results_.size() || b >= query_results_.size()) return -1.0;
  return double(query_results_[b] - query_results_[a]) * ctx_.limits().timestampPeriod * 1e-6;
}

}  // namespace tfm
