// The renderer-like host of the recording tests (test_embedding_recording*.cpp): its own buffers,
// images, command pool, command buffer and fence, made with the loader's functions, and a
// fixture that lends its device to tfmatch and fails a test on any validation message.
#pragma once

#include <vulkan/vulkan.h>  // the loader's prototypes first, as such a host includes them

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "host_device.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/recording.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm::test {

// The host's own objects, made and destroyed with the loader's functions.
class Host {
 public:
  explicit Host(HostDevice& device) : d_(device) {
    VkCommandPoolCreateInfo pi{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
    pi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pi.queueFamilyIndex = d_.queue_family();
    EXPECT_EQ(vkCreateCommandPool(d_.device(), &pi, nullptr, &pool_), VK_SUCCESS);
    VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    ai.commandPool = pool_;
    ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ai.commandBufferCount = 1;
    EXPECT_EQ(vkAllocateCommandBuffers(d_.device(), &ai, &cmd_), VK_SUCCESS);
    VkFenceCreateInfo fi{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    EXPECT_EQ(vkCreateFence(d_.device(), &fi, nullptr, &fence_), VK_SUCCESS);
  }
  ~Host() {
    vkDeviceWaitIdle(d_.device());
    for (VkImageView v : views_) vkDestroyImageView(d_.device(), v, nullptr);
    for (VkImage i : images_) vkDestroyImage(d_.device(), i, nullptr);
    for (VkBuffer b : buffers_) vkDestroyBuffer(d_.device(), b, nullptr);
    for (VkDeviceMemory m : memories_) vkFreeMemory(d_.device(), m, nullptr);
    vkDestroyFence(d_.device(), fence_, nullptr);
    vkDestroyCommandPool(d_.device(), pool_, nullptr);
  }

  // A host-visible buffer (the host fills and reads it through `mapped`).
  VkBuffer buffer(uint64_t bytes, void** mapped) {
    VkBufferCreateInfo bi{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
    bi.size = bytes;
    bi.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT |
               VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    VkBuffer b = VK_NULL_HANDLE;
    EXPECT_EQ(vkCreateBuffer(d_.device(), &bi, nullptr, &b), VK_SUCCESS);
    buffers_.push_back(b);
    VkMemoryRequirements req{};
    vkGetBufferMemoryRequirements(d_.device(), b, &req);
    VkDeviceMemory m = allocate(req, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
    EXPECT_EQ(vkBindBufferMemory(d_.device(), b, m, 0), VK_SUCCESS);
    EXPECT_EQ(vkMapMemory(d_.device(), m, 0, VK_WHOLE_SIZE, 0, mapped), VK_SUCCESS);
    return b;
  }
  // A 1D image of `width` texels of `format`, sampled by the host's shaders and written by copies.
  VkImage image_1d(VkFormat format, uint32_t width) { return image(VK_IMAGE_TYPE_1D, format, {width, 1, 1}); }
  // An image of `type`, sampled by the host's shaders and written and read by copies, in
  // device-local memory.
  VkImage image(VkImageType type, VkFormat format, VkExtent3D extent) {
    VkImageCreateInfo ii{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
    ii.imageType = type;
    ii.format = format;
    ii.extent = extent;
    ii.mipLevels = 1;
    ii.arrayLayers = 1;
    ii.samples = VK_SAMPLE_COUNT_1_BIT;
    ii.tiling = VK_IMAGE_TILING_OPTIMAL;
    ii.usage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
    ii.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    VkImage made = VK_NULL_HANDLE;
    EXPECT_EQ(vkCreateImage(d_.device(), &ii, nullptr, &made), VK_SUCCESS);
    images_.push_back(made);
    VkMemoryRequirements req{};
    vkGetImageMemoryRequirements(d_.device(), made, &req);
    EXPECT_EQ(vkBindImageMemory(d_.device(), made, allocate(req, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT), 0), VK_SUCCESS);
    return made;
  }

  // A view of all of `image` (3D, mip 0, layer 0), destroyed with the host.
  VkImageView view_3d(VkImage image, VkFormat format) {
    VkImageViewCreateInfo vi{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
    vi.image = image;
    vi.viewType = VK_IMAGE_VIEW_TYPE_3D;
    vi.format = format;
    vi.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    VkImageView view = VK_NULL_HANDLE;
    EXPECT_EQ(vkCreateImageView(d_.device(), &vi, nullptr, &view), VK_SUCCESS);
    views_.push_back(view);
    return view;
  }

  // A 3D volume image of `format`, filled with `texels` (x fastest) by the host's own copy in
  // `cmd` and left in SHADER_READ_ONLY_OPTIMAL for its compute shaders, as a renderer keeps the
  // volumes it samples. `staging` must stay alive until the host's wait.
  VkImage volume_image(VkCommandBuffer cmd, VkFormat format, VkExtent3D extent, const std::vector<uint8_t>& texels,
                       VkBuffer& staging) {
    const VkImage made = image(VK_IMAGE_TYPE_3D, format, extent);
    void* map = nullptr;
    staging = buffer(texels.size() + 4, &map);
    std::memcpy(map, texels.data(), texels.size());
    VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
    b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    b.image = made;
    b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0,
                         nullptr, 1, &b);
    VkBufferImageCopy region{};
    region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    region.imageExtent = extent;
    vkCmdCopyBufferToImage(cmd, staging, made, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
    b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 0, nullptr, 0,
                         nullptr, 1, &b);
    return made;
  }

  VkCommandBuffer begin() {
    EXPECT_EQ(vkResetCommandBuffer(cmd_, 0), VK_SUCCESS);
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    EXPECT_EQ(vkBeginCommandBuffer(cmd_, &bi), VK_SUCCESS);
    return cmd_;
  }
  // Ends, submits on the host's queue with the host's fence, and waits.
  void submit_and_wait() {
    EXPECT_EQ(vkEndCommandBuffer(cmd_), VK_SUCCESS);
    VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd_;
    EXPECT_EQ(vkQueueSubmit(d_.queue(), 1, &si, fence_), VK_SUCCESS);
    EXPECT_EQ(vkWaitForFences(d_.device(), 1, &fence_, VK_TRUE, UINT64_MAX), VK_SUCCESS);
    EXPECT_EQ(vkResetFences(d_.device(), 1, &fence_), VK_SUCCESS);
  }
  // The host's own writes of its volume (copies, as a renderer streams data in) and the barrier
  // that orders them before tfmatch's compute-shader reads (NormalEquationsRecorder::access()).
  static void write_volume(VkCommandBuffer cmd, VkBuffer staging, VkBuffer volume, const std::vector<VkBufferCopy>& regions) {
    vkCmdCopyBuffer(cmd, staging, volume, uint32_t(regions.size()), regions.data());
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = NormalEquationsRecorder::access().reads;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, NormalEquationsRecorder::access().stages, 0, 1, &b, 0,
                         nullptr, 0, nullptr);
  }
  // Copies row 0 of `image` (in TRANSFER_SRC_OPTIMAL after tfmatch's upload) into `dst` and makes
  // it visible to the host.
  void read_image(VkCommandBuffer cmd, VkImage image, uint32_t width, VkBuffer dst) {
    VkBufferImageCopy region{};
    region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    region.imageExtent = {width, 1, 1};
    vkCmdCopyImageToBuffer(cmd, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, dst, 1, &region);
    host_barrier(cmd);
  }
  // Makes earlier writes (transfers by default) visible to the host after its wait.
  static void host_barrier(VkCommandBuffer cmd, VkPipelineStageFlags stages = VK_PIPELINE_STAGE_TRANSFER_BIT,
                           VkAccessFlags writes = VK_ACCESS_TRANSFER_WRITE_BIT) {
    VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    b.srcAccessMask = writes;
    b.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, stages, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &b, 0, nullptr, 0, nullptr);
  }

 private:
  VkDeviceMemory allocate(const VkMemoryRequirements& req, VkMemoryPropertyFlags wanted) {
    VkPhysicalDeviceMemoryProperties props{};
    vkGetPhysicalDeviceMemoryProperties(d_.physical(), &props);
    uint32_t type = 0;
    while (type < props.memoryTypeCount &&
           !((req.memoryTypeBits >> type & 1u) && (props.memoryTypes[type].propertyFlags & wanted) == wanted))
      ++type;
    EXPECT_LT(type, props.memoryTypeCount);
    VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = type;
    VkDeviceMemory m = VK_NULL_HANDLE;
    EXPECT_EQ(vkAllocateMemory(d_.device(), &ai, nullptr, &m), VK_SUCCESS);
    memories_.push_back(m);
    return m;
  }
  HostDevice& d_;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  std::vector<VkBuffer> buffers_;
  std::vector<VkImage> images_;
  std::vector<VkImageView> views_;
  std::vector<VkDeviceMemory> memories_;
};

// Two fields with structure at every scale, NaN here and there (no data), awkward sizes.
inline void make_fields(uint64_t voxels, std::vector<float>& ref, std::vector<float>& opt) {
  ref.resize(voxels);
  opt.resize(voxels);
  for (uint64_t i = 0; i < voxels; ++i) {
    const double s = double(i) / double(voxels);
    ref[i] = float(0.5 + 0.45 * std::sin(37.0 * s) * std::cos(5.0 * s));
    opt[i] = float(std::pow(double(ref[i]), 1.7) * 3.0 + 0.01 * std::sin(1000.0 * s));
    if (i % 997 == 13) opt[i] = NAN;
  }
}

// Member m's value at voxel v of the tests' ensembles: series that differ from voxel to voxel
// and from member to member, in [-1.3, 1.3].
inline double member_value(uint32_t m, uint64_t v) {
  return std::sin(0.37 * m + 0.011 * double(v)) + 0.3 * std::cos(1.7 * m * m + double(v % 13));
}

inline TransferFunction reference_tf(double shift) {
  TransferFunction tf;
  for (int j = 0; j < 7; ++j) {
    const double t = j / 6.0;
    tf.rgba.push_back({t, std::fmod(t + shift, 1.0), 1.0 - t, 0.1 + 0.8 * t * t});
  }
  return tf;
}

// Each test is a host: its own device (validation with synchronization validation when
// installed), lent to tfmatch, and its own objects; every validation message fails the test.
class EmbeddingRecording : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(device_.create());
    ctx_ = Context::adopt(device_.external());
    host_ = std::make_unique<Host>(device_);
  }
  void TearDown() override {
    host_.reset();
    ctx_.reset();  // tfmatch lets go of the device before the host destroys it
    EXPECT_EQ(device_.wait_idle(), VK_SUCCESS);
    for (const auto& m : device_.messages()) ADD_FAILURE() << "validation: " << m;
  }
  HostDevice device_;
  std::unique_ptr<Context> ctx_;
  std::unique_ptr<Host> host_;
};

}  // namespace tfm::test
