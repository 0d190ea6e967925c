// Recording and submitting compute work: dispatches with bindings and push constants, barriers,
// copies and GPU timestamps, in one command buffer with its own fence and descriptor pool.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include <vulkan/vulkan_core.h>

namespace tfm {

class Buffer;
class ComputePipeline;
class Context;

// One binding of a dispatch: a whole buffer, or several buffers for an array binding, for a
// storage-buffer binding; or, made by texels(), a range of one buffer seen as texels of `format`
// for a uniform-texel-buffer binding (the batch makes the buffer view and keeps it alive).
struct Binding {
  Binding(const Buffer& b);  // NOLINT(google-explicit-constructor): bindings read as lists
  Binding(std::vector<const Buffer*> array);
  // `offset` must be a multiple of the device's minTexelBufferOffsetAlignment and the range (the
  // rest of the buffer when VK_WHOLE_SIZE) at most maxTexelBufferElements texels.
  static Binding texels(const Buffer& b, VkFormat format, uint64_t offset = 0, uint64_t range = VK_WHOLE_SIZE);
  // An array binding of texel buffers: each whole buffer seen as texels of `format`.
  static Binding texels(std::vector<const Buffer*> array, VkFormat format);
  // A sampled image (a host's view, in `layout` while the work runs), read without a sampler.
  static Binding image(VkImageView view, VkImageLayout layout);
  std::vector<const Buffer*> buffers;
  VkImageView image_view = VK_NULL_HANDLE;  // set for image bindings
  VkImageLayout image_layout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkFormat texel_format = VK_FORMAT_UNDEFINED;  // set for texel bindings
  uint64_t texel_offset = 0, texel_range = VK_WHOLE_SIZE;
};

struct Groups {
  uint32_t x = 1, y = 1, z = 1;
};

class CommandBatch {
 public:
  explicit CommandBatch(Context& ctx);
  // A batch that records into a host's command buffer `cmd` (in the recording state, from a pool
  // of the context's queue family) instead of its own: the host submits it and waits for it, so
  // submit(), wait() and timestamps are not available (std::logic_error). The batch owns the
  // descriptor sets and buffer views its dispatches use: keep it until the host's wait for that
  // submission has returned (destroying it earlier frees what the device may still read).
  CommandBatch(Context& ctx, VkCommandBuffer cmd);
  // Starts recording into `cmd` again (a batch made with a host's command buffer only): the
  // descriptor sets and buffer views of the last recording are released, their pools kept for
  // reuse. The host's wait for the last recording must have returned.
  void restart(VkCommandBuffer cmd);
  ~CommandBatch();
  CommandBatch(const CommandBatch&) = delete;
  CommandBatch& operator=(const CommandBatch&) = delete;

  // Records a dispatch. Throws std::logic_error when the bindings or push-constant size do not
  // match the pipeline, std::runtime_error when the group count exceeds the device's limits.
  void dispatch(const ComputePipeline& pipeline, std::span<const Binding> bindings,
                const void* push, uint32_t push_bytes, Groups groups);
  void dispatch(const ComputePipeline& pipeline, std::initializer_list<Binding> bindings, const void* push,
                uint32_t push_bytes, Groups groups) {
    dispatch(pipeline, std::span<const Binding>(bindings.begin(), bindings.size()), push, push_bytes, groups);
  }
  template <class Push>
  void dispatch(const ComputePipeline& pipeline, std::span<const Binding> bindings, const Push& push, Groups groups) {
    static_assert(std::is_trivially_copyable_v<Push>);
    dispatch(pipeline, bindings, &push, sizeof(Push), groups);
  }
  template <class Push>
  void dispatch(const ComputePipeline& pipeline, std::initializer_list<Binding> bindings, const Push& push,
                Groups groups) {
    dispatch(pipeline, std::span<const Binding>(bindings.begin(), bindings.size()), push, groups);
  }
  // Orders all earlier compute and transfer writes before later compute and transfer accesses.
  void barrier();
  // Makes every earlier compute and transfer write visible to the host once the host's fence or
  // semaphore wait for this work returns (what submit() records at the end of an own batch).
  void barrier_to_host();
  void copy(const Buffer& src, uint64_t src_offset, const Buffer& dst, uint64_t dst_offset, uint64_t bytes);
  void fill(Buffer& dst, uint32_t value);
  // Writes `bytes` (a multiple of 4) of host data into `dst` at `offset` (a multiple of 4) from
  // within the command buffer (vkCmdUpdateBuffer, in pieces of at most 64 KiB): small tables, no
  // staging memory to keep alive.
  void update(const Buffer& dst, uint64_t offset, const void* data, uint64_t bytes);
  // Copies `width` texels from the start of `src` into row 0 of mip level 0, layer 0 of `image`
  // (a 1D or 2D colour image of `format`'s texel size), moving it from `old_layout` to
  // TRANSFER_DST_OPTIMAL first and to `new_layout` after, where `dst_stages`/`dst_access` (the
  // host's next use) wait for the copy. Earlier transfer writes to `src` are ordered before it.
  void copy_to_image(const Buffer& src, VkImage image, uint32_t width, VkImageLayout old_layout,
                     VkImageLayout new_layout, VkPipelineStageFlags dst_stages, VkAccessFlags dst_access);
  // Transfer copies out of a host's images, in three steps: begin_image_copies orders the host's
  // last writes of each image (src_stages/src_access) and every earlier compute and transfer
  // access of this batch before transfer reads, moving each image to TRANSFER_SRC_OPTIMAL unless it
  // is in GENERAL or already there; copy_image_voxels copies any number of voxel ranges; then
  // end_image_copies makes the copies visible to compute-shader reads and returns each image to
  // its layout before the host's next use (dst_stages/dst_access).
  struct HostImage {
    VkImage image = VK_NULL_HANDLE;
    VkImageLayout layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    VkPipelineStageFlags src_stages = 0;  // 0: nothing to wait for
    VkAccessFlags src_access = 0;
    VkPipelineStageFlags dst_stages = 0;  // 0: nothing waits
    VkAccessFlags dst_access = 0;
  };
  void begin_image_copies(std::span<const HostImage> images);
  // Voxels [first, first + count) of mip 0, layer 0 of `image` (`extent` texels of `texel_bytes`,
  // x fastest, voxel (z ny + y) nx + x) into `dst` from `dst_offset`, tightly packed: at most five
  // copy regions (a partial row, rows, slices, rows, a partial row). Between begin and end only.
  void copy_image_voxels(const HostImage& image, VkExtent3D extent, uint32_t texel_bytes, uint64_t first,
                         uint64_t count, const Buffer& dst, uint64_t dst_offset);
  void end_image_copies(std::span<const HostImage> images);
  // Copies the whole of mip level 0, layer 0 of the 3D (or 2D) colour image `image` (`extent`
  // texels, x fastest, tightly packed) into `dst` from `dst_offset` (a multiple of the texel size).
  // The image is in `layout` and usable as a transfer source; unless that is TRANSFER_SRC_OPTIMAL
  // or GENERAL it moves to TRANSFER_SRC_OPTIMAL for the copy and back after. The host's earlier
  // accesses `src_stages`/`src_access` (its writes of the image) are ordered before the copy, and
  // its next use `dst_stages`/`dst_access` after it; earlier compute and transfer accesses of
  // `dst` finish first, and the copy is made visible to compute-shader reads.
  void copy_from_image(VkImage image, VkExtent3D extent, VkImageLayout layout, VkPipelineStageFlags src_stages,
                       VkAccessFlags src_access, VkPipelineStageFlags dst_stages, VkAccessFlags dst_access,
                       const Buffer& dst, uint64_t dst_offset);
  // Writes a GPU timestamp after all earlier work; returns its slot. A batch holds 128: later
  // ones (and all on a device without timestamps) are not written, and their times are -1.
  uint32_t timestamp();
  // Submits, waits for completion (device writes then visible to the host) and resets nothing:
  // a batch is submitted once.
  void submit_and_wait();
  // The same in two steps, so the host can work while the device runs the batch: submit() once,
  // then wait() (again a no-op). Destroying a submitted batch waits for it.
  void submit();
  void wait();
  // Milliseconds between timestamp slots a and b (after submit_and_wait); -1 without timestamps.
  double elapsed_ms(uint32_t a, uint32_t b) const;

 private:
  VkDescriptorSet allocate_set(VkDescriptorSetLayout layout);
  Context& ctx_;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  std::vector<VkDescriptorPool> descriptor_pools_;
  size_t current_pool_ = 0;  // the pool allocate_set takes sets from; later ones are empty
  std::vector<VkBufferView> buffer_views_;  // of texel bindings, destroyed with the batch
  VkQueryPool queries_ = VK_NULL_HANDLE;
  uint32_t query_count_ = 0;
  std::vector<uint64_t> query_results_;
  bool submitted_ = false, waited_ = false;
  bool external_ = false;  // recording into a host's command buffer
};

}  // namespace tfm
