// A renderer-like host that keeps its volumes in its own device buffer and re-fits a TF inside its
// own command buffers (kernels/recording.h): tfmatch reads the host's buffer in place, records
// into the host's command buffer and never submits; the host submits, waits on its fence, reads
// the O(N) result, solves and records the TF's upload into its own buffer and 1D images. The
// validation layer with synchronization validation watches the host's command buffers.
#include <vulkan/vulkan.h>  // the loader's prototypes first, as such a host includes them

#include <cmath>
#include <algorithm>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>

#include <glm/gtc/packing.hpp>
#include <gtest/gtest.h>

#include "buffer.h"
#include "commands.h"
#include "context.h"
#include "correlation.h"
#include "histogram.h"
#include "device_field.h"
#include "gpu_voxel_ops.h"
#include "gradient_descent.h"
#include "host_device.h"
#include "memory_budget.h"
#include "normal_equations.h"
#include "recording.h"
#include "render.h"
#include "render_settings.h"
#include "residual.h"
#include "sparse_ops.h"
#include "volume.h"

namespace tfm {
namespace {

// The host's own objects, made and destroyed with the loader's functions.
class Host {
 public:
  explicit Host(test::HostDevice& device) : d_(device) {
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
  test::HostDevice& d_;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  std::vector<VkBuffer> buffers_;
  std::vector<VkImage> images_;
  std::vector<VkImageView> views_;
  std::vector<VkDeviceMemory> memories_;
};

// Two fields with structure at every scale, NaN here and there (no data), awkward sizes.
void make_fields(uint64_t voxels, std::vector<float>& ref, std::vector<float>& opt) {
  ref.resize(voxels);
  opt.resize(voxels);
  for (uint64_t i = 0; i < voxels; ++i) {
    const double s = double(i) / double(voxels);
    ref[i] = float(0.5 + 0.45 * std::sin(37.0 * s) * std::cos(5.0 * s));
    opt[i] = float(std::pow(double(ref[i]), 1.7) * 3.0 + 0.01 * std::sin(1000.0 * s));
    if (i % 997 == 13) opt[i] = NAN;
  }
}

TransferFunction reference_tf(double shift) {
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
  test::HostDevice device_;
  std::unique_ptr<Context> ctx_;
  std::unique_ptr<Host> host_;
};

TEST_F(EmbeddingRecording, AssemblyAndTfUploadRecordIntoTheHostsCommandBuffers) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    // The host's volume buffer holds both fields, the second at an offset that is not a chunk
    // boundary's; small chunks (max_chunk_voxels) make each adopted field span several views.
    const uint64_t voxels = 20000 + 37, chunk = 4096;
    const uint64_t align = 256;  // a multiple of every device's storage/texel offset alignment (<= 256)
    const uint64_t opt_offset = (voxels * 4 + align - 1) / align * align + align;
    std::vector<float> ref, opt;
    make_fields(voxels, ref, opt);
    void* volume_map = nullptr;
    void* staging_map = nullptr;
    VkBuffer volume = host.buffer(opt_offset + voxels * 4, &volume_map);
    VkBuffer staging = host.buffer(voxels * 4 * 2, &staging_map);
    std::memcpy(staging_map, ref.data(), voxels * 4);
    std::memcpy(static_cast<char*>(staging_map) + voxels * 4, opt.data(), voxels * 4);

    const uint32_t n = 24;
    const FieldMapping rm = make_mapping({0.05, 0.95}, 7), om = make_mapping({0.0, 2.6}, n);
    DeviceField ref_field = DeviceField::adopt(ctx, volume, 0, voxels, "host ref", chunk);
    DeviceField opt_field = DeviceField::adopt(ctx, volume, opt_offset, voxels, "host opt", chunk);
    EXPECT_GT(ref_field.chunk_count(), 1u);
    NormalEquationsRecorder recorder(ctx, n);
    TfUploadRecorder uploader(ctx);

    for (double shift : {0.0, 0.37}) {  // two frames, the reference TF edited in between
      SCOPED_TRACE("reference TF shift " + std::to_string(shift));
      const TransferFunction tf = reference_tf(shift);
      const std::vector<float> tf_floats = tf.as_floats();
      const uint64_t submissions = ctx.submissions();
      VkCommandBuffer cmd = host.begin();
      if (shift == 0.0)  // the host streams its volume in once
        Host::write_volume(cmd, staging, volume, {{0, 0, voxels * 4}, {voxels * 4, opt_offset, voxels * 4}});
      recorder.record_assemble(cmd, ref_field, opt_field, rm, om, tf_floats);
      EXPECT_EQ(ctx.submissions(), submissions) << "record_assemble submitted work";
      host.submit_and_wait();
      const std::vector<uint64_t> recorded = recorder.fixed_point_slots();
      const NormalEquations eq = recorder.result();
      EXPECT_EQ(ctx.submissions(), submissions) << "reading the result submitted work";

      // The same system from host arrays through tfmatch's own submissions: the same bits, for
      // this chunking and the device's own.
      for (uint64_t own_chunk : {chunk, uint64_t(0)}) {
        DeviceField r(ctx, ref, "ref", own_chunk), o(ctx, opt, "opt", own_chunk);
        Buffer tfb = upload_tf(ctx, tf, "tf");
        GpuNormalEquations blocking(ctx, n);
        blocking.add(r, o, rm, om, tfb);
        EXPECT_EQ(recorded, blocking.fixed_point_slots()) << "chunk " << own_chunk;
      }
      EXPECT_EQ(eq.voxels, voxels - (voxels - 14) / 997 - 1);  // NaN voxels carry no equation

      // Solve on the host; the next frame's command buffer writes the TF into the host's buffer
      // and into 1D images of three formats.
      const SolveResult solved = solve_normal_equations(eq);
      const std::vector<float> fitted = solved.tf.as_floats();
      void* tf_map = nullptr;
      VkBuffer tf_buffer = host.buffer(64 + fitted.size() * 4, &tf_map);
      struct Readback {
        VkFormat format;
        VkImage image;
        VkBuffer buffer;
        void* map;
      };
      std::vector<Readback> images;
      for (VkFormat f : {VK_FORMAT_R32G32B32A32_SFLOAT, VK_FORMAT_R16G16B16A16_SFLOAT, VK_FORMAT_R8G8B8A8_UNORM}) {
        Readback r{f, host.image_1d(f, n), VK_NULL_HANDLE, nullptr};
        r.buffer = host.buffer(n * 16, &r.map);
        images.push_back(r);
      }
      std::vector<std::unique_ptr<TfUploadRecorder>> image_uploaders;  // one per image: each keeps its staging
      const uint64_t before_upload = ctx.submissions();
      cmd = host.begin();
      uploader.record_tf_upload(cmd, fitted, TfBufferTarget{tf_buffer, 64, fitted.size() * 4});
      Host::host_barrier(cmd);
      for (const Readback& r : images) {
        TfImageTarget target;
        target.image = r.image;
        target.format = r.format;
        target.new_layout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;  // the host copies it back to check
        target.dst_stages = VK_PIPELINE_STAGE_TRANSFER_BIT;
        target.dst_access = VK_ACCESS_TRANSFER_READ_BIT;
        image_uploaders.push_back(std::make_unique<TfUploadRecorder>(ctx));
        image_uploaders.back()->record_tf_upload(cmd, fitted, target);
        host.read_image(cmd, r.image, n, r.buffer);
      }
      EXPECT_EQ(ctx.submissions(), before_upload) << "record_tf_upload submitted work";
      host.submit_and_wait();
      EXPECT_EQ(0, std::memcmp(static_cast<char*>(tf_map) + 64, fitted.data(), fitted.size() * 4));
      for (const Readback& r : images) {
        const std::vector<uint8_t> expected = encode_tf_texels(fitted, r.format);
        EXPECT_EQ(0, std::memcmp(r.map, expected.data(), expected.size())) << "format " << int(r.format);
      }
    }
    // Host memory does not grow with the volume: a recording over 2 x 8 M voxels of the host's
    // buffer (64 MiB) adds far less than one field to the process (pipelines exist by now).
    const uint64_t big = 8u << 20;
    void* big_map = nullptr;
    VkBuffer big_volume = host.buffer(big * 8, &big_map);
    std::memset(big_map, 0, big * 8);
    for (uint64_t i = 0; i < 2 * big; i += 4096) static_cast<float*>(big_map)[i] = float(i % 7) / 6.0f;
    DeviceField big_ref = DeviceField::adopt(ctx, big_volume, 0, big, "big ref");
    DeviceField big_opt = DeviceField::adopt(ctx, big_volume, big * 4, big, "big opt");
    const std::vector<float> tf_floats = reference_tf(0.0).as_floats();
    const uint64_t before = resident_memory();
    VkCommandBuffer cmd = host.begin();
    recorder.record_assemble(cmd, big_ref, big_opt, rm, om, tf_floats);
    host.submit_and_wait();
    EXPECT_EQ(recorder.result().voxels, big);
    const uint64_t grown = resident_memory() - std::min(before, resident_memory());
    EXPECT_LT(grown, uint64_t(8) << 20) << "recording over a 32 MiB field grew host memory by " << grown << " bytes";
  }
}

// The host lends the recorders its scratch memory (one buffer: accumulators, then the result at an
// aligned offset): the same system and the same voxel loss as in the recorders' own memory, read
// through the host's mapping.
TEST_F(EmbeddingRecording, AssemblyInTheHostsScratchMemory) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const uint64_t voxels = 5000 + 1;
    std::vector<float> ref, opt;
    make_fields(voxels, ref, opt);
    void* map = nullptr;
    const uint64_t opt_offset = (voxels * 4 + 255) / 256 * 256;
    VkBuffer volume = host.buffer(opt_offset + voxels * 4, &map);
    std::memcpy(map, ref.data(), voxels * 4);
    std::memcpy(static_cast<char*>(map) + opt_offset, opt.data(), voxels * 4);
    const DeviceField r = DeviceField::adopt(ctx, volume, 0, voxels, "host ref");
    const DeviceField o = DeviceField::adopt(ctx, volume, opt_offset, voxels, "host opt");
    const uint32_t n = 16;
    const uint64_t bytes = NormalEquationsRecorder::scratch_bytes(n), result_offset = (bytes + 255) / 256 * 256;
    void* scratch_map = nullptr;
    VkBuffer scratch = host.buffer(result_offset + bytes, &scratch_map);
    RecorderScratch lent{scratch, 0, scratch, result_offset, static_cast<char*>(scratch_map) + result_offset};
    NormalEquationsRecorder in_host_memory(ctx, n, lent), in_own_memory(ctx, n);
    const FieldMapping rm = make_mapping({0.05, 0.95}, 7), om = make_mapping({0.0, 2.6}, n);
    const std::vector<float> tf = reference_tf(0.1).as_floats();
    VkCommandBuffer cmd = host.begin();
    in_host_memory.record_assemble(cmd, r, o, rm, om, tf);
    in_own_memory.record_assemble(cmd, r, o, rm, om, tf);
    host.submit_and_wait();
    EXPECT_EQ(in_host_memory.fixed_point_slots(), in_own_memory.fixed_point_slots());
    EXPECT_GT(in_host_memory.result().voxels, 0u);
    RecorderScratch unmapped = lent;
    unmapped.result_mapped = nullptr;
    EXPECT_THROW(NormalEquationsRecorder(ctx, n, unmapped), std::invalid_argument);
    // The voxel loss in the same scratch buffer (its ranges are smaller).
    ASSERT_LE(VoxelLossRecorder::scratch_bytes(), bytes);
    VoxelLossRecorder loss_in_host_memory(ctx, lent), loss_in_own_memory(ctx);
    const std::vector<float> second_tf = reference_tf(0.6).as_floats();
    const FieldMapping om7 = make_mapping({0.0, 2.6}, 7);
    cmd = host.begin();
    loss_in_host_memory.record_voxel_loss(cmd, r, o, rm, om7, tf, second_tf);
    loss_in_own_memory.record_voxel_loss(cmd, r, o, rm, om7, tf, second_tf);
    host.submit_and_wait();
    const VoxelLoss a = loss_in_host_memory.result(), b = loss_in_own_memory.result();
    EXPECT_EQ(a.squared, b.squared);
    EXPECT_EQ(a.absolute, b.absolute);
    EXPECT_EQ(a.voxels, b.voxels);
    EXPECT_GT(a.voxels, 0u);
    EXPECT_THROW(VoxelLossRecorder(ctx, unmapped), std::invalid_argument);
    // The renderer's stop indices in the host's memory: the same picture; an image larger than
    // the scratch is refused before anything is recorded.
    const VolumeGeometry geometry = VolumeGeometry::from({25, 20, 10}, {1.0, 1.0, 1.0});
    const DeviceField grid_field = DeviceField::adopt(ctx, volume, 0, 25 * 20 * 10, "host ref, 25x20x10");  // its first voxels
    RenderSettings s;
    s.width = 23;
    s.height = 17;
    void* stop_map = nullptr;
    VkBuffer stop = host.buffer(1024 + RenderRecorder::stop_scratch_bytes(s.width, s.height), &stop_map);
    RenderRecorder render_in_host_memory(ctx, geometry, 1, stop, 1024, RenderRecorder::stop_scratch_bytes(s.width, s.height));
    RenderRecorder render_in_own_memory(ctx, geometry, 1);
    void* pictures_map = nullptr;
    const uint64_t picture_bytes = uint64_t(s.width) * s.height * 16;
    VkBuffer pictures = host.buffer(2 * picture_bytes, &pictures_map);
    Buffer first = Buffer::adopt(ctx, pictures, 0, picture_bytes, "picture, host stop scratch");
    Buffer second = Buffer::adopt(ctx, pictures, picture_bytes, picture_bytes, "picture, own stop indices");
    cmd = host.begin();
    render_in_host_memory.record_render(cmd, grid_field, om7, second_tf, s, first);
    render_in_own_memory.record_render(cmd, grid_field, om7, second_tf, s, second);
    Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
    host.submit_and_wait();
    EXPECT_EQ(0, std::memcmp(pictures_map, static_cast<char*>(pictures_map) + picture_bytes, picture_bytes));
    RenderSettings larger = s;
    larger.width += 1;
    Buffer both = Buffer::adopt(ctx, pictures, 0, 2 * picture_bytes, "pictures");  // room for the larger image
    cmd = host.begin();
    try {
      render_in_host_memory.record_render(cmd, grid_field, om7, second_tf, larger, both);
      ADD_FAILURE() << "an image larger than the host's stop scratch was recorded";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("stop scratch"), std::string::npos) << e.what();
    }
    host.submit_and_wait();
  }
}

// The residual map into the host's own buffer and the voxel loss, recorded: the same bits as the
// blocking calls on tfmatch's own copies of the fields.
TEST_F(EmbeddingRecording, ResidualMapAndVoxelLossRecordIntoTheHostsCommandBuffers) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const uint64_t voxels = 9000 + 3, chunk = 2048;
    std::vector<float> ref, opt;
    make_fields(voxels, ref, opt);
    void* volume_map = nullptr;
    void* residual_map_memory = nullptr;
    VkBuffer volume = host.buffer(2 * voxels * 4 + 1024, &volume_map);
    VkBuffer residual = host.buffer(voxels * 4, &residual_map_memory);
    const uint64_t opt_offset = (voxels * 4 + 255) / 256 * 256;
    std::memcpy(volume_map, ref.data(), voxels * 4);
    std::memcpy(static_cast<char*>(volume_map) + opt_offset, opt.data(), voxels * 4);
    DeviceField ref_field = DeviceField::adopt(ctx, volume, 0, voxels, "host ref", chunk);
    DeviceField opt_field = DeviceField::adopt(ctx, volume, opt_offset, voxels, "host opt", chunk);
    DeviceField out = DeviceField::adopt(ctx, residual, 0, voxels, "host residual", chunk);
    const TransferFunction ref_tf = reference_tf(0.2), opt_tf = reference_tf(0.6);
    const FieldMapping rm = make_mapping({0.05, 0.95}, 7), om = make_mapping({0.0, 2.6}, 7);

    ResidualMapRecorder residual_recorder(ctx);
    VoxelLossRecorder loss_recorder(ctx);
    const uint64_t submissions = ctx.submissions();
    VkCommandBuffer cmd = host.begin();
    residual_recorder.record_residual_map(cmd, ref_field, opt_field, rm, om, ref_tf.as_floats(), opt_tf.as_floats(), out);
    loss_recorder.record_voxel_loss(cmd, ref_field, opt_field, rm, om, ref_tf.as_floats(), opt_tf.as_floats());
    Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, ResidualMapRecorder::access().writes);
    EXPECT_EQ(ctx.submissions(), submissions);
    host.submit_and_wait();

    DeviceField r(ctx, ref, "ref", chunk), o(ctx, opt, "opt", chunk);
    Buffer rt = upload_tf(ctx, ref_tf, "ref tf"), ot = upload_tf(ctx, opt_tf, "opt tf");
    Volume grid;
    grid.dims = {voxels, 1, 1};
    const Volume expected = residual_map_gpu(ctx, grid, r, o, rm, om, rt, ot);
    EXPECT_EQ(0, std::memcmp(residual_map_memory, expected.values.data(), voxels * 4));
    const VoxelLoss blocking = voxel_loss_gpu(ctx, r, o, rm, om, rt, ot);
    const VoxelLoss recorded = loss_recorder.result();
    EXPECT_EQ(recorded.squared, blocking.squared);
    EXPECT_EQ(recorded.absolute, blocking.absolute);
    EXPECT_EQ(recorded.voxels, blocking.voxels);
    EXPECT_GT(recorded.mae(), 0.0);
  }
}

// tfmatch's renderer recorded into the host's buffer: the pixels GpuRenderer::render_colours
// Correlation fields of an ensemble in the host's buffer (member-major), recorded: the bits of
// CorrelationKernel::compute on the same values, for strategies of one invocation and of one
// workgroup per voxel, and NaN everywhere for a reference series with NaN.
TEST_F(EmbeddingRecording, CorrelationOfAnEnsembleInTheHostsBuffer) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const uint64_t voxels = 3000 + 7;
    struct Case {
      CorrelationMeasure measure;
      uint32_t members;
    };
    for (const Case& k : {Case{CorrelationMeasure::Pearson, 10}, Case{CorrelationMeasure::Spearman, 12},
                          Case{CorrelationMeasure::Kendall, 40}, Case{CorrelationMeasure::MiBinned, 40},
                          Case{CorrelationMeasure::MiKraskov, 9}}) {
      CorrelationParams params;
      params.measure = k.measure;
      SCOPED_TRACE(std::string(correlation_measure_name(k.measure)) + ", " + std::to_string(k.members) + " members");
      std::vector<float> values(uint64_t(k.members) * voxels);
      for (uint32_t m = 0; m < k.members; ++m)
        for (uint64_t v = 0; v < voxels; ++v)
          values[m * voxels + v] = float(std::sin(0.37 * m + 0.011 * double(v)) + 0.3 * std::cos(1.7 * m * m + double(v % 13)));
      void* ensemble_map = nullptr;
      void* out_map = nullptr;
      VkBuffer ensemble = host.buffer(values.size() * 4, &ensemble_map);
      VkBuffer out = host.buffer(voxels * 4, &out_map);
      std::memcpy(ensemble_map, values.data(), values.size() * 4);
      Buffer ensemble_view = Buffer::adopt(ctx, ensemble, 0, values.size() * 4, "host ensemble");
      Buffer out_view = Buffer::adopt(ctx, out, 0, voxels * 4, "host correlation field");
      const EnsembleView view{values.data(), k.members, voxels};
      const std::vector<float> reference = ensemble_series(view, 1234);

      CorrelationRecorder recorder(ctx);
      const uint64_t submissions = ctx.submissions();
      VkCommandBuffer cmd = host.begin();
      recorder.record_correlation(cmd, ensemble_view, voxels, reference, params, out_view);
      Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT);
      EXPECT_EQ(ctx.submissions(), submissions);
      host.submit_and_wait();
      const std::vector<float> expected = CorrelationKernel(ctx).compute(view, reference, params);
      EXPECT_EQ(0, std::memcmp(out_map, expected.data(), voxels * 4));
      if (k.measure == CorrelationMeasure::Pearson || k.measure == CorrelationMeasure::Spearman ||
          k.measure == CorrelationMeasure::Kendall)
        EXPECT_FLOAT_EQ(static_cast<const float*>(out_map)[1234], 1.0f);  // the reference point itself
      // As if beyond one texel view: chunks of 448 voxels copied on the device (7 of them, the last
      // 319), into a field at an aligned offset of the host's buffer: the same bits.
      {
        void* chunked_map = nullptr;
        VkBuffer chunked_out = host.buffer(256 + voxels * 4, &chunked_map);
        Buffer chunked_view = Buffer::adopt(ctx, chunked_out, 256, voxels * 4, "host correlation field, chunked");
        CorrelationRecorder chunked(ctx, 448);
        cmd = host.begin();
        chunked.record_correlation(cmd, ensemble_view, voxels, reference, params, chunked_view);
        Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT);
        host.submit_and_wait();
        EXPECT_EQ(0, std::memcmp(static_cast<const char*>(chunked_map) + 256, expected.data(), voxels * 4)) << "chunked";
      }

      std::vector<float> with_nan = reference;
      with_nan[2] = NAN;
      cmd = host.begin();
      recorder.record_correlation(cmd, ensemble_view, voxels, with_nan, params, out_view);
      Host::host_barrier(cmd);
      host.submit_and_wait();
      const float* field = static_cast<const float*>(out_map);
      EXPECT_TRUE(std::all_of(field, field + voxels, [](float x) { return std::isnan(x); }));
    }
  }
}

// An ensemble stored in each field format (float32, float16, unorm16, unorm8), in the host's
// buffer or as one 3D image per member: the correlation field of the numbers a texel fetch gives
// (CorrelationKernel::compute on those floats), bit for bit, whole and in chunks of 128 voxels that
// start mid-row and mid-slice of the images, for both strategies (one invocation, one workgroup per
// voxel). A unorm code converts as the device does (FieldsInHalfAndUnormFormatsEqualTheirFloatValues:
// the rounded quotient or the code times the rounded reciprocal), the same way every time.
TEST_F(EmbeddingRecording, CorrelationOfEnsemblesInEveryFormatAsBuffersAndImages) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const VkExtent3D extent{13, 7, 5};
    const uint64_t voxels = 13 * 7 * 5;
    struct Case {
      CorrelationMeasure measure;
      uint32_t members;
    };
    for (FieldFormat format : {FieldFormat::Float32, FieldFormat::Float16, FieldFormat::Unorm16, FieldFormat::Unorm8}) {
      const uint32_t bytes = field_format_bytes(format);
      const double unorm_max = format == FieldFormat::Unorm16 ? 65535.0 : 255.0;
      std::optional<bool> by_quotient;  // how this device converts unorm codes
      for (const Case& k : {Case{CorrelationMeasure::Pearson, 10}, Case{CorrelationMeasure::Spearman, 40},
                            Case{CorrelationMeasure::Kendall, 12}, Case{CorrelationMeasure::MiBinned, 12},
                            Case{CorrelationMeasure::MiKraskov, 9}}) {
        CorrelationParams params;
        params.measure = k.measure;
        SCOPED_TRACE(std::string(field_format_name(format)) + ", " + correlation_measure_name(k.measure) + ", " +
                     std::to_string(k.members) + " members");
        // Stored numbers in [0, 1] (ties in the unorm8 codes), and the floats they stand for.
        const uint64_t values = uint64_t(k.members) * voxels;
        std::vector<uint8_t> stored(values * bytes);
        std::vector<float> quotient(values), reciprocal(values);
        for (uint32_t m = 0; m < k.members; ++m)
          for (uint64_t v = 0; v < voxels; ++v) {
            const uint64_t i = m * voxels + v;
            const double x = 0.5 + 0.3 * std::sin(0.37 * m + 0.011 * double(v)) + 0.15 * std::cos(1.7 * m * m + double(v % 13));
            if (format == FieldFormat::Float32) {
              quotient[i] = reciprocal[i] = float(x);
              std::memcpy(stored.data() + 4 * i, &quotient[i], 4);
            } else if (format == FieldFormat::Float16) {
              const uint16_t h = glm::packHalf1x16(float(x));
              std::memcpy(stored.data() + 2 * i, &h, 2);
              quotient[i] = reciprocal[i] = glm::unpackHalf1x16(h);
            } else {
              const uint32_t code = uint32_t(std::lround(x * unorm_max));
              std::memcpy(stored.data() + i * bytes, &code, bytes);
              quotient[i] = float(double(code) / unorm_max);
              reciprocal[i] = float(code) * float(1.0 / unorm_max);
            }
          }
        const std::vector<float> reference = ensemble_series(EnsembleView{quotient.data(), k.members, voxels}, 200);
        CorrelationKernel kernel(ctx);
        const std::vector<float> expected_quotient =
            kernel.compute(EnsembleView{quotient.data(), k.members, voxels}, reference, params);
        const std::vector<float> expected_reciprocal =
            kernel.compute(EnsembleView{reciprocal.data(), k.members, voxels}, reference, params);

        void* ensemble_map = nullptr;
        VkBuffer ensemble = host.buffer(stored.size() + 4, &ensemble_map);
        std::memcpy(ensemble_map, stored.data(), stored.size());
        const Buffer ensemble_view = Buffer::adopt(ctx, ensemble, 0, stored.size(), "host ensemble");
        std::vector<ImageFieldSource> images(k.members);
        std::vector<VkBuffer> stagings(k.members);
        const VkFormat vk_format = voxel_texel_format(format);
        VkCommandBuffer cmd = host.begin();
        for (uint32_t m = 0; m < k.members; ++m) {
          const std::vector<uint8_t> member(stored.begin() + m * voxels * bytes, stored.begin() + (m + 1) * voxels * bytes);
          images[m].image = host.volume_image(cmd, vk_format, extent, member, stagings[m]);
          images[m].format = vk_format;
          images[m].extent = extent;
          images[m].src_stages = VK_PIPELINE_STAGE_TRANSFER_BIT;  // the host's upload (volume_image)
          images[m].src_access = VK_ACCESS_TRANSFER_WRITE_BIT;
        }
        // Five fields: from the buffer and from the images, whole and in chunks of 128 voxels, and
        // from the images in chunks in the host's scratch memory (192 voxels a chunk, at an offset).
        const uint64_t stride = 2048;  // bytes between the fields: a multiple of every offset alignment
        void* out_map = nullptr;
        VkBuffer out = host.buffer(5 * stride, &out_map);
        std::vector<Buffer> out_views;
        for (uint64_t i = 0; i < 5; ++i)
          out_views.push_back(Buffer::adopt(ctx, out, i * stride, voxels * 4, "host correlation field"));
        void* scratch_map = nullptr;
        const uint64_t scratch_bytes = 3 * CorrelationKernel::min_chunk_bytes(k.members, format);
        VkBuffer scratch = host.buffer(256 + scratch_bytes, &scratch_map);
        CorrelationRecorder whole(ctx), chunked(ctx, 128), whole_images(ctx), chunked_images(ctx, 128);
        CorrelationRecorder in_scratch(ctx, scratch, 256, scratch_bytes);
        CorrelationRecorder too_small(ctx, scratch, 256, CorrelationKernel::min_chunk_bytes(k.members, format) - 1);
        const uint64_t submissions = ctx.submissions();
        whole.record_correlation(cmd, ensemble_view, format, voxels, reference, params, out_views[0]);
        chunked.record_correlation(cmd, ensemble_view, format, voxels, reference, params, out_views[1]);
        whole_images.record_correlation(cmd, images, reference, params, out_views[2]);
        chunked_images.record_correlation(cmd, images, reference, params, out_views[3]);
        in_scratch.record_correlation(cmd, images, reference, params, out_views[4]);
        EXPECT_THROW(too_small.record_correlation(cmd, images, reference, params, out_views[4]), std::invalid_argument);
        Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT);
        EXPECT_EQ(ctx.submissions(), submissions) << "nothing submitted while recording";
        host.submit_and_wait();
        const float* got = static_cast<const float*>(out_map);
        const bool quotient_here = std::memcmp(got, expected_quotient.data(), voxels * 4) == 0;
        if (!by_quotient) by_quotient = quotient_here;
        const std::vector<float>& expected = *by_quotient ? expected_quotient : expected_reciprocal;
        const char* what[] = {"buffer", "buffer, chunks of 128", "images", "images, chunks of 128",
                              "images, chunks in the host's scratch"};
        for (int i = 0; i < 5; ++i)
          EXPECT_EQ(0, std::memcmp(got + i * stride / 4, expected.data(), voxels * 4)) << what[i];
        EXPECT_GT(std::count_if(expected.begin(), expected.end(), [](float x) { return std::isfinite(x) && x != 0.0f; }),
                  int64_t(voxels / 2));
      }
    }
  }
}

// Fields stored as float16, unorm16 and unorm8 in the host's buffer, read in place: every kernel
// sees the floats a texel fetch gives, so the assembly, the voxel loss, the residual map, the
// histogram and the rendering equal those of float32 arrays holding the same values, bit for bit.
// float16 converts exactly; a unorm c converts to c / (2^b - 1) within Vulkan's precision, which
// devices meet either as the rounded quotient or as c times the rounded reciprocal (lavapipe): the
// test finds which from the assembly and holds every kernel to it.
TEST_F(EmbeddingRecording, FieldsInHalfAndUnormFormatsEqualTheirFloatValues) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const std::array<uint64_t, 3> dims{21, 17, 13};
    const uint64_t voxels = dims[0] * dims[1] * dims[2], chunk = 2048;
    std::vector<float> ref, opt;
    make_fields(voxels, ref, opt);
    for (FieldFormat format : {FieldFormat::Float16, FieldFormat::Unorm16, FieldFormat::Unorm8}) {
      SCOPED_TRACE(field_format_name(format));
      // The second field stored in `format` (values in [0, 1] for the unorm formats), and the
      // floats it stands for under each conversion.
      const double unorm_max = format == FieldFormat::Unorm16 ? 65535.0 : 255.0;
      std::vector<uint8_t> stored(voxels * field_format_bytes(format));
      std::vector<float> quotient(voxels), reciprocal(voxels);
      for (uint64_t v = 0; v < voxels; ++v) {
        const float x = std::isnan(opt[v]) ? 0.5f : std::clamp(opt[v] / 2.6f, 0.0f, 1.0f);
        uint32_t code = 0;
        if (format == FieldFormat::Float16) {
          const uint16_t h = glm::packHalf1x16(std::isnan(opt[v]) ? NAN : opt[v]);
          std::memcpy(stored.data() + 2 * v, &h, 2);
          quotient[v] = reciprocal[v] = glm::unpackHalf1x16(h);
          continue;
        }
        code = uint32_t(std::lround(x * unorm_max));
        std::memcpy(stored.data() + v * field_format_bytes(format), &code, field_format_bytes(format));
        quotient[v] = float(double(code) / unorm_max);
        reciprocal[v] = float(code) * float(1.0 / unorm_max);
      }
      void* map = nullptr;
      VkBuffer buffer = host.buffer(stored.size() + 4, &map);
      std::memcpy(map, stored.data(), stored.size());
      const DeviceField in_place = DeviceField::adopt(ctx, buffer, 0, voxels, "host field", chunk, format);
      const DeviceField r(ctx, ref, "ref", chunk);
      const TransferFunction ref_tf = reference_tf(0.3), opt_tf = reference_tf(0.7);
      const FieldMapping rm = make_mapping({0.05, 0.95}, 7);
      const FieldMapping om = make_mapping(format == FieldFormat::Float16 ? FieldRange{0.0, 2.6} : FieldRange{0.0, 1.0}, 7);
      Buffer rt = upload_tf(ctx, ref_tf, "ref tf"), ot = upload_tf(ctx, opt_tf, "opt tf");
      auto slots = [&](const DeviceField& field) {
        GpuNormalEquations eq(ctx, 7);
        eq.add(r, field, rm, om, rt);
        return eq.fixed_point_slots();
      };
      const std::vector<uint64_t> in_place_slots = slots(in_place);
      const DeviceField by_quotient(ctx, quotient, "floats (quotient)", chunk);
      const bool is_quotient = in_place_slots == slots(by_quotient);
      const DeviceField floats(ctx, is_quotient ? quotient : reciprocal, "floats", chunk);
      EXPECT_EQ(in_place_slots, slots(floats)) << "assembly: neither conversion of the unorm codes";
      const VoxelLoss la = voxel_loss_gpu(ctx, r, in_place, rm, om, rt, ot), lb = voxel_loss_gpu(ctx, r, floats, rm, om, rt, ot);
      EXPECT_EQ(la.squared, lb.squared) << "voxel loss";
      EXPECT_EQ(la.absolute, lb.absolute) << "voxel loss";
      Volume grid;
      grid.dims = dims;
      EXPECT_EQ(residual_map_gpu(ctx, grid, r, in_place, rm, om, rt, ot).values,
                residual_map_gpu(ctx, grid, r, floats, rm, om, rt, ot).values) << "residual map";
      FieldHistogramKernel histogram(ctx, 32);
      EXPECT_EQ(histogram.run(in_place, 0.0, 1.0).bins, histogram.run(floats, 0.0, 1.0).bins) << "histogram";
      RenderSettings s;
      s.width = 31;
      s.height = 29;
      const VolumeGeometry geometry = VolumeGeometry::from(dims, {1.0, 1.0, 1.0});
      EXPECT_EQ(GpuRenderer(ctx, in_place, geometry).render_colours(om, ot, s).rgba,
                GpuRenderer(ctx, floats, geometry).render_colours(om, ot, s).rgba) << "rendering";
      // Gradient descent's gradient pass and CGLS's prepare pass (the reference in float32, the
      // second field in the format; and both in the format).
      GdGradientKernel gd(ctx, 7, false);
      auto gradient = [&](const DeviceField& field) {
        Buffer accum(ctx, gd_accumulator_bytes(7), MemoryUsage::Device, "gd accumulators");
        CommandBatch batch(ctx);
        batch.fill(accum, 0u);
        batch.barrier();
        gd.record(batch, r, field, rm, om, rt, ot, accum);
        batch.submit_and_wait();
        std::vector<uint32_t> words(accum.size() / 4);
        readback(ctx, accum, words.data(), accum.size());
        return words;
      };
      EXPECT_EQ(gradient(in_place), gradient(floats)) << "gradient descent";
      SparsePrepareKernel prepare(ctx);
      auto prepared = [&](const DeviceField& first, const DeviceField& second, const FieldMapping& first_map,
                          const Buffer& first_tf) {
        VoxelVectors vectors(ctx, first, second, 1000);  // vector chunks inside field chunks: shifted views
        CommandBatch batch(ctx);
        prepare.record(batch, first, second, first_map, om, first_tf, vectors);
        batch.submit_and_wait();
        return std::make_pair(vectors.read_coords(ctx), vectors.read_rgba(ctx));
      };
      EXPECT_EQ(prepared(r, in_place, rm, rt), prepared(r, floats, rm, rt)) << "CGLS prepare, mixed formats";
      EXPECT_EQ(prepared(in_place, in_place, om, ot), prepared(floats, floats, om, ot)) << "CGLS prepare";
    }
  }
}

// The host's volumes as 3D images in every field format (R32_SFLOAT, R16_SFLOAT, R16_UNORM,
// R8_UNORM): ImageFieldRecorder copies each on the device into a field, and the assembly, the voxel
// loss, the residual map and the rendering recorded after it in the same command buffer give the
// bits of the same stored values in a buffer (DeviceField::adopt), on an awkward extent split into
// chunks, twice (the recorders restarted on the next frame); so do the assembly, the voxel loss and
// the residual map reading both images in place (ImageFieldView, no copy). Members of an ensemble copied from
// R32F images into the host's member-major buffer give the correlation field of those values.
TEST_F(EmbeddingRecording, VolumesAsImagesOfEveryFormatGiveTheirBufferBits) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const VkExtent3D extent{21, 17, 13};
    const std::array<uint64_t, 3> dims{21, 17, 13};
    const uint64_t voxels = dims[0] * dims[1] * dims[2], chunk = 2048;
    std::vector<float> ref, opt;
    make_fields(voxels, ref, opt);
    const DeviceField r(ctx, ref, "ref", chunk);
    const TransferFunction ref_tf = reference_tf(0.3), opt_tf = reference_tf(0.7);
    const std::vector<float> ref_floats = ref_tf.as_floats(), opt_floats = opt_tf.as_floats();
    const FieldMapping rm = make_mapping({0.05, 0.95}, 7);
    Buffer rt = upload_tf(ctx, ref_tf, "ref tf"), ot = upload_tf(ctx, opt_tf, "opt tf");
    RenderSettings s;
    s.width = 31;
    s.height = 29;
    const VolumeGeometry geometry = VolumeGeometry::from(dims, {1.0, 1.0, 1.0});
    for (VkFormat vk_format : {VK_FORMAT_R32_SFLOAT, VK_FORMAT_R16_SFLOAT, VK_FORMAT_R16_UNORM, VK_FORMAT_R8_UNORM}) {
      const FieldFormat format = field_format_of(vk_format, "test");
      SCOPED_TRACE(field_format_name(format));
      // The second field's stored texels: floats, halves, or unorm codes of values in [0, 1].
      const uint32_t bytes = field_format_bytes(format);
      std::vector<uint8_t> stored(voxels * bytes);
      for (uint64_t v = 0; v < voxels; ++v) {
        if (format == FieldFormat::Float32) {
          std::memcpy(stored.data() + 4 * v, &opt[v], 4);
        } else if (format == FieldFormat::Float16) {
          const uint16_t h = glm::packHalf1x16(opt[v]);
          std::memcpy(stored.data() + 2 * v, &h, 2);
        } else {
          const double unorm_max = format == FieldFormat::Unorm16 ? 65535.0 : 255.0;
          const float x = std::isnan(opt[v]) ? 0.5f : std::clamp(opt[v] / 2.6f, 0.0f, 1.0f);
          const uint32_t code = uint32_t(std::lround(x * unorm_max));
          std::memcpy(stored.data() + v * bytes, &code, bytes);
        }
      }
      const bool unorm = format == FieldFormat::Unorm16 || format == FieldFormat::Unorm8;
      const FieldMapping om = make_mapping(unorm ? FieldRange{0.0, 1.0} : FieldRange{0.0, 2.6}, 7);
      void* map = nullptr;
      VkBuffer buffer = host.buffer(stored.size() + 4, &map);
      std::memcpy(map, stored.data(), stored.size());
      const DeviceField in_buffer = DeviceField::adopt(ctx, buffer, 0, voxels, "host buffer", chunk, format);
      void* residual_map = nullptr;
      void* picture_map = nullptr;
      VkBuffer residual = host.buffer(voxels * 4, &residual_map);
      VkBuffer picture = host.buffer(uint64_t(s.width) * s.height * 16, &picture_map);
      DeviceField residual_field = DeviceField::adopt(ctx, residual, 0, voxels, "host residual", chunk);
      Buffer picture_view = Buffer::adopt(ctx, picture, 0, uint64_t(s.width) * s.height * 16, "host picture");

      ImageFieldRecorder copier(ctx, extent, vk_format, "second volume", chunk);
      ASSERT_EQ(copier.field().chunk_count(), in_buffer.chunk_count());
      NormalEquationsRecorder assembly(ctx, 7);
      ReductionOptions ranges;  // dispatches of 64 quads: ranges that start inside the image
      ranges.range_quads = 64;
      NormalEquationsRecorder in_place(ctx, 7, ranges);
      ResidualMapRecorder residual_in_place(ctx);
      VoxelLossRecorder loss_in_place(ctx);
      void* residual2_map = nullptr;
      VkBuffer residual2 = host.buffer(voxels * 4, &residual2_map);
      DeviceField residual2_field = DeviceField::adopt(ctx, residual2, 0, voxels, "host residual, images in place");
      VkImage ref_image = VK_NULL_HANDLE;
      VkBuffer ref_staging = VK_NULL_HANDLE;
      std::vector<uint8_t> ref_texels(voxels * 4);
      std::memcpy(ref_texels.data(), ref.data(), ref_texels.size());
      VoxelLossRecorder loss(ctx);
      ResidualMapRecorder residual_recorder(ctx);
      RenderRecorder render(ctx, geometry, uint32_t(copier.field().chunk_count()));
      RenderRecorder render_in_place(ctx, geometry, 1);
      void* picture2_map = nullptr;
      VkBuffer picture2 = host.buffer(uint64_t(s.width) * s.height * 16, &picture2_map);
      Buffer picture2_view = Buffer::adopt(ctx, picture2, 0, uint64_t(s.width) * s.height * 16, "host picture, in place");
      VkBuffer staging = VK_NULL_HANDLE;
      VkImage image = VK_NULL_HANDLE;
      for (int frame = 0; frame < 2; ++frame) {
        SCOPED_TRACE("frame " + std::to_string(frame));
        const uint64_t submissions = ctx.submissions();
        VkCommandBuffer cmd = host.begin();
        if (frame == 0) {
          image = host.volume_image(cmd, vk_format, extent, stored, staging);
          ref_image = host.volume_image(cmd, VK_FORMAT_R32_SFLOAT, extent, ref_texels, ref_staging);
        }
        ImageFieldSource source;
        source.image = image;
        source.format = vk_format;
        source.extent = extent;
        copier.record_copy(cmd, source);
        assembly.record_assemble(cmd, r, copier.field(), rm, om, ref_floats);
        loss.record_voxel_loss(cmd, r, copier.field(), rm, om, ref_floats, opt_floats);
        residual_recorder.record_residual_map(cmd, r, copier.field(), rm, om, ref_floats, opt_floats, residual_field);
        render.record_render(cmd, copier.field(), om, opt_floats, s, picture_view);
        // The assembly reading both images in place (no copy).
        const ImageFieldView ref_view{host.view_3d(ref_image, VK_FORMAT_R32_SFLOAT), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL,
                                      extent};
        const ImageFieldView opt_view{host.view_3d(image, vk_format), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, extent};
        in_place.record_assemble(cmd, ref_view, opt_view, rm, om, ref_floats);
        residual_in_place.record_residual_map(cmd, ref_view, opt_view, rm, om, ref_floats, opt_floats, residual2_field);
        loss_in_place.record_voxel_loss(cmd, ref_view, opt_view, rm, om, ref_floats, opt_floats);
        render_in_place.record_render(cmd, opt_view, om, opt_floats, s, picture2_view);
        Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                           VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
        EXPECT_EQ(ctx.submissions(), submissions) << "recording submitted work";
        host.submit_and_wait();

        GpuNormalEquations eq(ctx, 7);
        eq.add(r, in_buffer, rm, om, rt);
        EXPECT_EQ(assembly.fixed_point_slots(), eq.fixed_point_slots()) << "assembly";
        EXPECT_EQ(in_place.fixed_point_slots(), eq.fixed_point_slots()) << "assembly reading the images in place";
        const VoxelLoss expected_loss = voxel_loss_gpu(ctx, r, in_buffer, rm, om, rt, ot), got_loss = loss.result();
        EXPECT_EQ(got_loss.squared, expected_loss.squared) << "voxel loss";
        EXPECT_EQ(got_loss.absolute, expected_loss.absolute) << "voxel loss";
        EXPECT_GT(got_loss.voxels, voxels / 2);
        const VoxelLoss in_place_loss = loss_in_place.result();
        EXPECT_EQ(in_place_loss.squared, expected_loss.squared) << "voxel loss, images in place";
        EXPECT_EQ(in_place_loss.absolute, expected_loss.absolute) << "voxel loss, images in place";
        EXPECT_EQ(in_place_loss.voxels, expected_loss.voxels);
        Volume grid;
        grid.dims = dims;
        const std::vector<float> expected_residual = residual_map_gpu(ctx, grid, r, in_buffer, rm, om, rt, ot).values;
        EXPECT_EQ(0, std::memcmp(residual_map, expected_residual.data(), voxels * 4)) << "residual map";
        EXPECT_EQ(0, std::memcmp(residual2_map, expected_residual.data(), voxels * 4)) << "residual map, images in place";
        const RenderedImage expected_picture = GpuRenderer(ctx, in_buffer, geometry).render_colours(om, ot, s);
        EXPECT_EQ(0, std::memcmp(picture_map, expected_picture.rgba.data(), expected_picture.rgba.size() * 4))
            << "rendering";
        EXPECT_EQ(0, std::memcmp(picture2_map, expected_picture.rgba.data(), expected_picture.rgba.size() * 4))
            << "rendering the image in place";
      }
    }

    // An ensemble of R32F member images copied into the host's member-major buffer (member m at
    // m V floats: V a multiple of 64 so every member starts at an aligned offset).
    const VkExtent3D member_extent{17, 8, 8};
    const uint64_t member_voxels = 17 * 8 * 8;
    const uint32_t members = 9;
    std::vector<float> values(members * member_voxels);
    for (uint32_t m = 0; m < members; ++m)
      for (uint64_t v = 0; v < member_voxels; ++v)
        values[m * member_voxels + v] = float(std::sin(0.37 * m + 0.011 * double(v)) + 0.3 * std::cos(1.7 * m * m + double(v % 13)));
    void* ensemble_map = nullptr;
    void* out_map = nullptr;
    VkBuffer ensemble = host.buffer(values.size() * 4, &ensemble_map);
    VkBuffer out = host.buffer(member_voxels * 4, &out_map);
    std::vector<std::unique_ptr<ImageFieldRecorder>> copiers;
    std::vector<VkBuffer> stagings(members);
    VkCommandBuffer cmd = host.begin();
    for (uint32_t m = 0; m < members; ++m) {
      std::vector<uint8_t> texels(member_voxels * 4);
      std::memcpy(texels.data(), values.data() + m * member_voxels, texels.size());
      ImageFieldSource source;
      source.image = host.volume_image(cmd, VK_FORMAT_R32_SFLOAT, member_extent, texels, stagings[m]);
      source.extent = member_extent;
      copiers.push_back(std::make_unique<ImageFieldRecorder>(ctx, member_extent, VK_FORMAT_R32_SFLOAT, "member", ensemble,
                                                             m * member_voxels * 4));
      copiers.back()->record_copy(cmd, source);
    }
    const EnsembleView view{values.data(), members, member_voxels};
    const std::vector<float> reference = ensemble_series(view, 77);
    CorrelationParams params;
    CorrelationRecorder correlation(ctx);
    Buffer ensemble_view = Buffer::adopt(ctx, ensemble, 0, values.size() * 4, "host ensemble");
    Buffer out_view = Buffer::adopt(ctx, out, 0, member_voxels * 4, "host correlation field");
    correlation.record_correlation(cmd, ensemble_view, member_voxels, reference, params, out_view);
    Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
    host.submit_and_wait();
    EXPECT_EQ(0, std::memcmp(ensemble_map, values.data(), values.size() * 4)) << "the members' copies";
    const std::vector<float> expected = CorrelationKernel(ctx).compute(view, reference, params);
    EXPECT_EQ(0, std::memcmp(out_map, expected.data(), member_voxels * 4)) << "correlation";
  }
}

// tfmatch's renderer recorded into the host's image buffer: the picture GpuRenderer::render_colours
// gives, bit for bit, for a field in the host's buffer spanning several chunks.
TEST_F(EmbeddingRecording, RenderRecordsIntoTheHostsImageBuffer) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    const std::array<uint64_t, 3> dims{23, 19, 17};
    const uint64_t voxels = dims[0] * dims[1] * dims[2], chunk = 2048;
    std::vector<float> values, unused;
    make_fields(voxels, values, unused);
    void* volume_map = nullptr;
    void* image_map = nullptr;
    VkBuffer volume = host.buffer(voxels * 4, &volume_map);
    std::memcpy(volume_map, values.data(), voxels * 4);
    RenderSettings s;
    s.width = 45;
    s.height = 37;
    s.camera.azimuth_deg = 33.0;
    s.camera.elevation_deg = 21.0;
    VkBuffer image = host.buffer(uint64_t(s.width) * s.height * 16, &image_map);
    DeviceField field = DeviceField::adopt(ctx, volume, 0, voxels, "host volume", chunk);
    Buffer image_view = Buffer::adopt(ctx, image, 0, uint64_t(s.width) * s.height * 16, "host image");
    const VolumeGeometry geometry = VolumeGeometry::from(dims, {1.0, 1.0, 1.0});
    const TransferFunction tf = reference_tf(0.4);
    const FieldMapping map = make_mapping({0.05, 0.95}, uint32_t(tf.size()));

    RenderRecorder recorder(ctx, geometry, uint32_t(field.chunk_count()));
    const uint64_t submissions = ctx.submissions();
    VkCommandBuffer cmd = host.begin();
    recorder.record_render(cmd, field, map, tf.as_floats(), s, image_view);
    Host::host_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, RenderRecorder::access().writes);
    EXPECT_EQ(ctx.submissions(), submissions);
    host.submit_and_wait();

    DeviceField own(ctx, values, "own volume", chunk);
    Buffer tf_buffer = upload_tf(ctx, tf, "tf");
    const RenderedImage expected = GpuRenderer(ctx, own, geometry).render_colours(map, tf_buffer, s);
    ASSERT_EQ(expected.rgba.size(), uint64_t(s.width) * s.height * 4);
    EXPECT_EQ(0, std::memcmp(image_map, expected.rgba.data(), expected.rgba.size() * 4));
    double alpha = 0.0;
    for (size_t i = 3; i < expected.rgba.size(); i += 4) alpha += expected.rgba[i];
    EXPECT_GT(alpha, 1.0);  // the picture is not empty
  }
}

TEST_F(EmbeddingRecording, BadArgumentsAreClearErrors) {
  Context& ctx = *ctx_;
  Host& host = *host_;
  {
    void* map = nullptr;
    VkBuffer volume = host.buffer(1 << 16, &map);
    EXPECT_THROW(DeviceField::adopt(ctx, VK_NULL_HANDLE, 0, 100, "f"), std::invalid_argument);
    EXPECT_THROW(DeviceField::adopt(ctx, volume, 4, 100, "f"), std::invalid_argument);  // misaligned
    DeviceField f = DeviceField::adopt(ctx, volume, 0, 1000, "f");
    NormalEquationsRecorder recorder(ctx, 8);
    EXPECT_THROW(recorder.result(), std::logic_error);  // nothing recorded yet
    const FieldMapping m = make_mapping({0, 1}, 8);
    const std::vector<float> three_entries(12, 0.5f);
    VkCommandBuffer cmd = host.begin();
    EXPECT_THROW(recorder.record_assemble(cmd, f, f, m, m, three_entries), std::invalid_argument);  // 3 vs 8
    TfUploadRecorder uploader(ctx);
    TfImageTarget bad;
    bad.image = host.image_1d(VK_FORMAT_R8G8B8A8_UNORM, 3);
    bad.format = VK_FORMAT_R8_UNORM;
    EXPECT_THROW(uploader.record_tf_upload(cmd, three_entries, bad), std::invalid_argument);
    EXPECT_THROW(uploader.record_tf_upload(cmd, three_entries, TfBufferTarget{volume, 0, 16}), std::invalid_argument);
    // Images: a format no field has, an empty extent, a misaligned host range, and a source whose
    // extent or format differs from the recorder's.
    EXPECT_THROW(ImageFieldRecorder(ctx, {4, 4, 4}, VK_FORMAT_R8G8B8A8_UNORM, "v"), std::invalid_argument);
    EXPECT_THROW(ImageFieldRecorder(ctx, {4, 0, 4}, VK_FORMAT_R32_SFLOAT, "v"), std::invalid_argument);
    EXPECT_THROW(ImageFieldRecorder(ctx, {4, 4, 4}, VK_FORMAT_R32_SFLOAT, "v", volume, 4), std::invalid_argument);
    ImageFieldRecorder copier(ctx, {4, 4, 4}, VK_FORMAT_R16_UNORM, "v");
    ImageFieldSource source;
    EXPECT_THROW(copier.record_copy(cmd, source), std::invalid_argument);  // no image
    source.image = bad.image;
    source.format = VK_FORMAT_R16_UNORM;
    source.extent = {4, 4, 5};
    EXPECT_THROW(copier.record_copy(cmd, source), std::invalid_argument);
    source.extent = {4, 4, 4};
    source.format = VK_FORMAT_R16_SFLOAT;
    EXPECT_THROW(copier.record_copy(cmd, source), std::invalid_argument);
    const ImageFieldView no_view{VK_NULL_HANDLE, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, {4, 4, 4}};
    EXPECT_THROW(recorder.record_assemble(cmd, no_view, no_view, m, m, std::vector<float>(32, 0.5f)), std::invalid_argument);
    ResidualMapRecorder residual(ctx);
    EXPECT_THROW(residual.record_residual_map(cmd, no_view, no_view, m, m, std::vector<float>(32, 0.5f),
                                              std::vector<float>(32, 0.5f), f),
                 std::invalid_argument);
    // Ensembles of member images: none, a missing image, members that differ, a format that is
    // no field format, fewer images than reference members; chunk scratch misaligned.
    CorrelationRecorder correlation(ctx);
    const std::vector<float> series{0.1f, 0.5f, 0.2f, 0.9f};
    Buffer out_view = Buffer::adopt(ctx, volume, 0, 256, "out");
    const ImageFieldSource member{VK_NULL_HANDLE, VK_FORMAT_R32_SFLOAT, {4, 4, 4}};
    EXPECT_THROW(correlation.record_correlation(cmd, std::span<const ImageFieldSource>{}, series, {}, out_view),
                 std::invalid_argument);
    std::vector<ImageFieldSource> members(4, member);
    EXPECT_THROW(correlation.record_correlation(cmd, members, series, {}, out_view), std::invalid_argument);
    members[0].image = members[1].image = members[2].image = members[3].image = host.image(VK_IMAGE_TYPE_3D, VK_FORMAT_R32_SFLOAT, {4, 4, 4});
    members[2].extent = {4, 4, 3};
    EXPECT_THROW(correlation.record_correlation(cmd, members, series, {}, out_view), std::invalid_argument);
    members[2].extent = {4, 4, 4};
    for (ImageFieldSource& m2 : members) m2.format = VK_FORMAT_R8G8B8A8_UNORM;
    EXPECT_THROW(correlation.record_correlation(cmd, members, series, {}, out_view), std::invalid_argument);
    for (ImageFieldSource& m2 : members) m2.format = VK_FORMAT_R32_SFLOAT;
    EXPECT_THROW(correlation.record_correlation(cmd, std::span(members).first(3), series, {}, out_view),
                 std::invalid_argument);
    EXPECT_THROW(CorrelationRecorder(ctx, volume, 4, 4096), std::invalid_argument);
    host.submit_and_wait();  // nothing was recorded: an empty command buffer
  }
}

}  // namespace
}  // namespace tfm
