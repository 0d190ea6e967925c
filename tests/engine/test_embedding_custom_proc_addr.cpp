// A host that hands tfmatch its own vkGetInstanceProcAddr (here a wrapper that records what is
// asked, then forwards to the loader): everything tfmatch calls on the adopted handles must be
// resolved through it, instance- and device-level alike. Through the same wrapper a host counts
// the commands tfmatch records into its command buffer: a recorder that refuses its arguments
// records none (the image overloads had recorded barriers, a table update and a fill first).
#include "adopted_device_check.h"
#include "host_device.h"
#include "recording_host.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/transfer_function.h"

#include <vulkan/vulkan.h>  // after tfmatch's headers: the loader's prototypes are still declared

#include <cstring>
#include <mutex>
#include <set>
#include <string>

#include <gtest/gtest.h>

namespace tfm {
namespace {

std::mutex requested_mutex;
std::set<std::string> requested;  // names asked of the host's resolvers
PFN_vkGetDeviceProcAddr loader_get_device_proc_addr = nullptr;

void record(const char* name) {
  std::lock_guard lock(requested_mutex);
  requested.insert(name);
}

// Commands recorded through the host's functions, by the wrappers below (the ones a recorder
// starts with: barriers, table updates, fills, copies, pipelines, dispatches).
int recorded_commands = 0;
PFN_vkCmdPipelineBarrier real_barrier = nullptr;
PFN_vkCmdUpdateBuffer real_update = nullptr;
PFN_vkCmdFillBuffer real_fill = nullptr;
PFN_vkCmdCopyBuffer real_copy = nullptr;
PFN_vkCmdBindPipeline real_bind = nullptr;
PFN_vkCmdDispatch real_dispatch = nullptr;

VKAPI_ATTR void VKAPI_CALL count_barrier(VkCommandBuffer c, VkPipelineStageFlags s, VkPipelineStageFlags d,
                                         VkDependencyFlags f, uint32_t mc, const VkMemoryBarrier* m, uint32_t bc,
                                         const VkBufferMemoryBarrier* b, uint32_t ic, const VkImageMemoryBarrier* i) {
  ++recorded_commands;
  real_barrier(c, s, d, f, mc, m, bc, b, ic, i);
}
VKAPI_ATTR void VKAPI_CALL count_update(VkCommandBuffer c, VkBuffer b, VkDeviceSize o, VkDeviceSize n, const void* d) {
  ++recorded_commands;
  real_update(c, b, o, n, d);
}
VKAPI_ATTR void VKAPI_CALL count_fill(VkCommandBuffer c, VkBuffer b, VkDeviceSize o, VkDeviceSize n, uint32_t v) {
  ++recorded_commands;
  real_fill(c, b, o, n, v);
}
VKAPI_ATTR void VKAPI_CALL count_copy(VkCommandBuffer c, VkBuffer s, VkBuffer d, uint32_t n, const VkBufferCopy* r) {
  ++recorded_commands;
  real_copy(c, s, d, n, r);
}
VKAPI_ATTR void VKAPI_CALL count_bind(VkCommandBuffer c, VkPipelineBindPoint p, VkPipeline pipeline) {
  ++recorded_commands;
  real_bind(c, p, pipeline);
}
VKAPI_ATTR void VKAPI_CALL count_dispatch(VkCommandBuffer c, uint32_t x, uint32_t y, uint32_t z) {
  ++recorded_commands;
  real_dispatch(c, x, y, z);
}

template <class F>
PFN_vkVoidFunction counted(F& real, F wrapper, PFN_vkVoidFunction found) {
  real = reinterpret_cast<F>(found);
  return reinterpret_cast<PFN_vkVoidFunction>(wrapper);
}

VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL host_get_device_proc_addr(VkDevice device, const char* name) {
  record(name);
  const PFN_vkVoidFunction found = loader_get_device_proc_addr(device, name);
  const std::string n = name;
  if (n == "vkCmdPipelineBarrier") return counted(real_barrier, &count_barrier, found);
  if (n == "vkCmdUpdateBuffer") return counted(real_update, &count_update, found);
  if (n == "vkCmdFillBuffer") return counted(real_fill, &count_fill, found);
  if (n == "vkCmdCopyBuffer") return counted(real_copy, &count_copy, found);
  if (n == "vkCmdBindPipeline") return counted(real_bind, &count_bind, found);
  if (n == "vkCmdDispatch") return counted(real_dispatch, &count_dispatch, found);
  return found;
}

VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL host_get_instance_proc_addr(VkInstance instance, const char* name) {
  record(name);
  // Device-level commands resolve through the host too when tfmatch asks for vkGetDeviceProcAddr here.
  if (std::strcmp(name, "vkGetDeviceProcAddr") == 0) {
    loader_get_device_proc_addr =
        reinterpret_cast<PFN_vkGetDeviceProcAddr>(vkGetInstanceProcAddr(instance, "vkGetDeviceProcAddr"));
    return reinterpret_cast<PFN_vkVoidFunction>(&host_get_device_proc_addr);
  }
  return vkGetInstanceProcAddr(instance, name);
}

TEST(EmbeddingCustomProcAddr, AdoptResolvesEverythingThroughTheHost) {
  test::HostDevice host;
  ASSERT_NO_FATAL_FAILURE(host.create());
  requested.clear();
  test::expect_adopted_device_computes(host.external(&host_get_instance_proc_addr));
  for (const char* name : {"vkGetDeviceProcAddr", "vkGetPhysicalDeviceProperties",
                           "vkGetPhysicalDeviceQueueFamilyProperties", "vkCreateBuffer", "vkQueueSubmit",
                           "vkCmdDispatch"})
    EXPECT_EQ(requested.count(name), 1u) << name << " was not resolved through the host's function";
  EXPECT_EQ(host.wait_idle(), VK_SUCCESS);
  for (const auto& m : host.messages()) ADD_FAILURE() << "validation: " << m;
}

// Each refused argument leaves the host's command buffer as it was: no command recorded, and the
// last recording (its descriptor sets) kept. Image views without a format, a residual output of
// another size than the images, an image of another extent than the renderer's grid, a TF target
// without its size, and the fields in buffers that the kernels refuse.
TEST(EmbeddingCustomProcAddr, RefusedArgumentsRecordNothing) {
  test::HostDevice device;
  ASSERT_NO_FATAL_FAILURE(device.create());
  {
    std::unique_ptr<Context> ctx = Context::adopt(device.external(&host_get_instance_proc_addr));
    test::Host host(device);
    VkCommandBuffer cmd = host.begin();
    const VkExtent3D extent{4, 4, 4};
    VkBuffer staging = VK_NULL_HANDLE;
    const VkImage image =
        host.volume_image(cmd, VK_FORMAT_R32_SFLOAT, extent, std::vector<uint8_t>(64 * 4, 0), staging);
    const VkImageView view = host.view_3d(image, VK_FORMAT_R32_SFLOAT);
    const ImageFieldView good{view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, extent, VK_FORMAT_R32_SFLOAT};
    ImageFieldView no_format = good, colour = good;
    no_format.format = VK_FORMAT_UNDEFINED;
    colour.format = VK_FORMAT_R8G8B8A8_UNORM;
    const FieldMapping m = make_mapping({0, 1}, 8);
    const std::vector<float> table(32, 0.5f);
    NormalEquationsRecorder assembly(*ctx, 8);
    VoxelLossRecorder loss(*ctx);
    ResidualMapRecorder residual(*ctx);
    DeviceField small_out(*ctx, 63, "residual of 63 voxels");
    RenderRecorder render(*ctx, VolumeGeometry::from({4, 4, 5}, {1, 1, 1}), 1);
    Buffer picture(*ctx, 16 * 16 * 16, MemoryUsage::Device, "picture");
    RenderSettings settings;
    settings.width = settings.height = 16;
    void* map = nullptr;
    const VkBuffer tf_buffer = host.buffer(1024, &map);
    TfUploadRecorder upload(*ctx);
    const int before = recorded_commands;
    EXPECT_THROW(assembly.record_assemble(cmd, no_format, good, m, m, table), std::invalid_argument);
    try {
      assembly.record_assemble(cmd, good, colour, m, m, table);
      ADD_FAILURE() << "a colour volume was taken for a field";
    } catch (const std::invalid_argument& e) {  // the format by name, not "image format 37"
      EXPECT_NE(std::string(e.what()).find("R8G8B8A8_UNORM is not a field format"), std::string::npos) << e.what();
    }
    EXPECT_THROW(loss.record_voxel_loss(cmd, good, no_format, m, m, table, table), std::invalid_argument);
    EXPECT_THROW(residual.record_residual_map(cmd, good, good, m, m, table, table, small_out), std::invalid_argument);
    EXPECT_THROW(render.record_render(cmd, good, m, table, settings, picture), std::invalid_argument);
    EXPECT_THROW(upload.record_tf_upload(cmd, table, TfBufferTarget{tf_buffer, 0}), std::invalid_argument);
    // Fields in buffers that the kernel, not the recorder, used to refuse (after recording the
    // tables): an output of another format, a second field of another size, a field of other
    // chunks than the renderer's pipeline.
    DeviceField ref_field(*ctx, 64, "ref"), short_field(*ctx, 60, "short"), out_field(*ctx, 64, "out");
    DeviceField chunked(*ctx, 80, "80 voxels in chunks of 8", 8);
    void* half_map = nullptr;
    const DeviceField half_out =
        DeviceField::adopt(*ctx, host.buffer(64 * 2, &half_map), 0, 64, "float16 out", 0, FieldFormat::Float16);
    EXPECT_THROW(residual.record_residual_map(cmd, ref_field, ref_field, m, m, table, table, const_cast<DeviceField&>(half_out)),
                 std::invalid_argument);
    EXPECT_THROW(residual.record_residual_map(cmd, ref_field, short_field, m, m, table, table, out_field),
                 std::invalid_argument);
    EXPECT_THROW(render.record_render(cmd, chunked, m, table, settings, picture), std::invalid_argument);
    // TFs past kMaxTableSize: the recorder, its scratch size and the blocking assembly refuse them.
    EXPECT_THROW(NormalEquationsRecorder(*ctx, 715827882u), std::invalid_argument);
    EXPECT_THROW(NormalEquationsRecorder::scratch_bytes(0x80000000u), std::invalid_argument);
    EXPECT_THROW(GpuNormalEquations(*ctx, uint32_t(kMaxTableSize) + 1), std::invalid_argument);
    EXPECT_EQ(recorded_commands, before) << "commands recorded by calls that threw";
    // The counting sees a recording that is accepted.
    assembly.record_assemble(cmd, good, good, m, m, table);
    EXPECT_GT(recorded_commands, before);
    host.submit_and_wait();
  }
  EXPECT_EQ(device.wait_idle(), VK_SUCCESS);
  for (const auto& msg : device.messages()) ADD_FAILURE() << "validation: " << msg;
}

}  // namespace
}  // namespace tfm
