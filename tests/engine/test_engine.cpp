// Engine: transfers, dispatch argument checks, split fields, result names, and argument checks of
// adoption (hosts that adopt their own device, with the loader or volk: tests/engine/).
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <thread>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/engine/vk_check.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/shaders/render_layout.h"
#include "tfmatch/shaders/shader_registry.h"
#include "tfmatch/shaders/shared_layout.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using EngineTest = test::GpuTest;

// Turns in-place transfers of host memory on or off for a test's scope, then restores them.
class HostImport {
 public:
  HostImport(Context& ctx, bool enabled) : ctx_(ctx), was_(ctx.host_import()) { ctx.set_host_import(enabled); }
  ~HostImport() { ctx_.set_host_import(was_); }

 private:
  Context& ctx_;
  bool was_;
};

TEST_F(EngineTest, UploadReadbackRoundTripThroughStaging) {
  const HostImport staged_only(ctx(), false);
  // Odd sizes; one larger than the two 32 MiB staging halves, so both are filled in turn while
  // the device copies the other; then small ones again through the staging the context kept.
  for (size_t words : {size_t(1), size_t(13), size_t(1027), (size_t(80) << 20) / 4 + 3, size_t(5), size_t(4099)}) {
    std::vector<uint32_t> data(words);
    std::iota(data.begin(), data.end(), 7u);
    Buffer b(ctx(), words * 4, MemoryUsage::Device, "roundtrip");
    EXPECT_FALSE(b.host_visible());
    upload(ctx(), b, data.data(), words * 4);
    std::vector<uint32_t> back(words, 0);
    readback(ctx(), b, back.data(), words * 4);
    ASSERT_EQ(std::memcmp(data.data(), back.data(), words * 4), 0) << words;
    // The second half again at an offset, from other values.
    const size_t half = words / 2;
    for (size_t i = half; i < words; ++i) data[i] = uint32_t(i * 2654435761u);
    upload(ctx(), b, data.data() + half, (words - half) * 4, half * 4);
    readback(ctx(), b, back.data(), words * 4);
    ASSERT_EQ(std::memcmp(data.data(), back.data(), words * 4), 0) << words << " at an offset";
  }
}

// `--json` timings: the device work an upload or a readback waits for is that transfer's time,
// staged or in place, never compute (it was all compute: a 41.5 M-voxel optimize reported 1 ms of
// upload beside its own 307 ms upload phase).
TEST_F(EngineTest, TransferWaitsCountAsTheTransferInThePhaseTimes) {
  const uint64_t bytes = (uint64_t(40) << 20) + 12;  // beyond one 32 MiB staging half
  std::vector<uint8_t> data(bytes, 7), back(bytes, 0);
  Buffer b(ctx(), bytes, MemoryUsage::Device, "timed transfer");
  auto seconds = [](Phase p) { return phase_times().seconds[static_cast<size_t>(p)]; };
  for (const bool in_place : {false, true}) {
    if (in_place && !ctx().host_import()) continue;
    SCOPED_TRACE(in_place ? "in place" : "staged");
    const HostImport mode(ctx(), in_place);
    const double compute0 = seconds(Phase::Compute), upload0 = seconds(Phase::Upload),
                 download0 = seconds(Phase::Download);
    upload(ctx(), b, data.data(), bytes);
    readback(ctx(), b, back.data(), bytes);
    EXPECT_EQ(seconds(Phase::Compute), compute0);
    EXPECT_GT(seconds(Phase::Upload), upload0);
    EXPECT_GT(seconds(Phase::Download), download0);
    ASSERT_EQ(back, data);
  }
}

TEST_F(EngineTest, LargeTransfersInPlaceGiveTheStagedBits) {
  if (!ctx().host_import()) GTEST_SKIP() << ctx().device_name() << " cannot import host memory (VK_EXT_external_memory_host)";
  const uint64_t align = ctx().min_import_alignment();
  ASSERT_GT(align, 0u);
  // Sizes at and past the threshold, starting 0, 1 and 3 words past an alignment boundary, so the
  // aligned interior goes in place and the unaligned head and tail through staging; offsets into
  // the device buffer that are not multiples of the alignment either.
  const size_t min_words = kHostImportMinBytes / 4;
  for (size_t words : {min_words, min_words + 1027, 3 * min_words + 13}) {
    for (size_t shift : {size_t(0), size_t(1), size_t(3)}) {
      SCOPED_TRACE(std::to_string(words) + " words, " + std::to_string(shift) + " past an alignment boundary");
      std::vector<uint32_t> storage(words + align);
      uint32_t* aligned = reinterpret_cast<uint32_t*>((reinterpret_cast<uintptr_t>(storage.data()) + align - 1) / align * align);
      uint32_t* data = aligned + shift;
      ASSERT_LE(data + words, storage.data() + storage.size());
      for (size_t i = 0; i < words; ++i) data[i] = uint32_t(i * 2654435761u + shift);
      const size_t dst_words = words + 5;
      Buffer b(ctx(), dst_words * 4, MemoryUsage::Device, "in place");
      {
        const HostImport staged(ctx(), false);
        std::vector<uint32_t> zeros(dst_words, 0xdeadbeefu);
        upload(ctx(), b, zeros.data(), dst_words * 4);
      }
      const uint64_t held = ctx().buffer_bytes();
      upload(ctx(), b, data, words * 4, 5 * 4);  // in place
      EXPECT_EQ(ctx().buffer_bytes(), held) << "an imported buffer allocates nothing";
      std::vector<uint32_t> staged_back(dst_words), in_place_back(dst_words + align);
      {
        const HostImport staged(ctx(), false);
        readback(ctx(), b, staged_back.data(), dst_words * 4);
      }
      uint32_t* dst = in_place_back.data() + 1;  // an unaligned destination too
      readback(ctx(), b, dst, dst_words * 4);
      for (size_t i = 0; i < 5; ++i) ASSERT_EQ(staged_back[i], 0xdeadbeefu) << "before the offset, word " << i;
      ASSERT_EQ(std::memcmp(staged_back.data() + 5, data, words * 4), 0) << "uploaded in place, read back staged";
      ASSERT_EQ(std::memcmp(dst, staged_back.data(), dst_words * 4), 0) << "read back in place";
    }
  }
}

// A batch holds 128 timestamps; later ones are not written and time -1, as on a device without
// timestamps, instead of throwing (DiffDVR asks for three per group of views: 3000 views of 8²
// pixels failed with "too many timestamps in one batch").
TEST_F(EngineTest, TimestampsPastTheBatchsPoolTimeMinusOne) {
  Buffer b(ctx(), 1024, MemoryUsage::Device, "stamped");
  CommandBatch batch(ctx());
  std::vector<uint32_t> slots;
  for (int i = 0; i < 200; ++i) {
    batch.fill(b, uint32_t(i));
    batch.barrier();
    slots.push_back(batch.timestamp());
  }
  batch.submit_and_wait();
  for (uint32_t k = 0; k < 200; ++k) ASSERT_EQ(slots[k], k);
  if (ctx().timestamps_supported()) {
    EXPECT_GE(batch.elapsed_ms(slots[0], slots[127]), 0.0);
  } else {
    EXPECT_EQ(batch.elapsed_ms(slots[0], slots[127]), -1.0);
  }
  EXPECT_EQ(batch.elapsed_ms(slots[0], slots[128]), -1.0);
  EXPECT_EQ(batch.elapsed_ms(slots[150], slots[199]), -1.0);
  uint32_t last = 0;
  readback(ctx(), b, &last, 4);
  EXPECT_EQ(last, 199u) << "the work after the last written timestamp ran";
}

TEST_F(EngineTest, ImportTakesOnlyAlignedHostMemory) {
  if (!ctx().host_import()) GTEST_SKIP() << ctx().device_name() << " cannot import host memory (VK_EXT_external_memory_host)";
  const uint64_t align = ctx().min_import_alignment();
  std::vector<char> storage(4 * align);
  char* aligned = reinterpret_cast<char*>((reinterpret_cast<uintptr_t>(storage.data()) + align - 1) / align * align);
  EXPECT_TRUE(Buffer::import_host(ctx(), aligned, align, "aligned"));
  EXPECT_FALSE(Buffer::import_host(ctx(), aligned + 4, align, "pointer off the alignment"));
  EXPECT_FALSE(Buffer::import_host(ctx(), aligned, align + 4, "size off the alignment"));
  EXPECT_FALSE(Buffer::import_host(ctx(), aligned, 0, "nothing"));
}

TEST_F(EngineTest, TransfersPastTheEndThrow) {
  Buffer b(ctx(), 16, MemoryUsage::Device, "small");
  uint32_t x[8] = {};
  EXPECT_THROW(upload(ctx(), b, x, 32), std::out_of_range);
  EXPECT_THROW(readback(ctx(), b, x, 8, 12), std::out_of_range);
}

TEST_F(EngineTest, DispatchChecksBindingsPushAndGroupLimits) {
  PipelineDesc desc;
  desc.shader = "voxel_loss";
  desc.spirv = shader_spirv(desc.shader);
  desc.binding_counts = {1, 1, 1, 1, 1, 1, 1};
  desc.binding_kinds = {DescriptorKind::UniformTexelBuffer, DescriptorKind::UniformTexelBuffer,
                        DescriptorKind::UniformTexelBuffer, DescriptorKind::UniformTexelBuffer,
                        DescriptorKind::StorageBuffer,      DescriptorKind::UniformTexelBuffer,
                        DescriptorKind::UniformTexelBuffer};
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  desc.specialization = {TFM_VOXEL_WORKGROUP};
  desc.workgroup_size = TFM_VOXEL_WORKGROUP;
  ComputePipeline pipe(ctx(), desc);
  Buffer b(ctx(), 256, MemoryUsage::Device, "b");
  const Binding t = Binding::texels(b, VK_FORMAT_R32G32B32A32_SFLOAT, 0, 256);
  gpu::VoxelPairPush push{};
  {
    CommandBatch batch(ctx());
    EXPECT_THROW(batch.dispatch(pipe, {t, t, t, t, b, t}, push, {1}), std::logic_error);
    EXPECT_THROW(batch.dispatch(pipe, {t, t, t, t, b, t, t}, &push, 4, {1}), std::logic_error);
    EXPECT_THROW(batch.dispatch(pipe, {t, t, t, t, b, t, t}, push, {ctx().limits().maxComputeWorkGroupCount[0] + 1u}),
                 std::runtime_error);
  }
  PipelineDesc too_big = desc;
  too_big.workgroup_size = ctx().limits().maxComputeWorkGroupInvocations + 1;
  EXPECT_THROW(ComputePipeline(ctx(), too_big), std::runtime_error);
  PipelineDesc no_code = desc;
  no_code.spirv = {};
  EXPECT_THROW(ComputePipeline(ctx(), no_code), std::invalid_argument);
}

// The context's pipelines are shared by description: the same one for an equal description, from
// any thread and made once; another for any difference; a creation that failed is tried again.
TEST_F(EngineTest, PipelinesAreSharedByDescription) {
  PipelineDesc desc;
  desc.shader = "voxel_loss";
  desc.spirv = shader_spirv(desc.shader);
  desc.binding_counts = {1, 1, 1, 1, 1, 1, 1};
  desc.binding_kinds = texel_binding_kinds(7, {0, 1, 2, 3, 5, 6});
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  desc.specialization = {TFM_VOXEL_WORKGROUP};
  desc.workgroup_size = TFM_VOXEL_WORKGROUP;
  PipelineRegistry& registry = ctx().pipelines();
  const size_t before = registry.size();
  std::vector<SharedPipeline> got(6);
  {
    std::vector<std::thread> askers;
    for (SharedPipeline& g : got) askers.emplace_back([&] { g = shared_pipeline(ctx(), desc); });
    for (std::thread& t : askers) t.join();
  }
  for (const SharedPipeline& g : got) {
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(g.get(), got[0].get());
  }
  EXPECT_LE(registry.size(), before + 1);  // + 0 when an earlier test's kernel made it already
  PipelineDesc other_constant = desc;  // another workgroup size
  other_constant.specialization = {TFM_VOXEL_WORKGROUP / 2};
  other_constant.workgroup_size = TFM_VOXEL_WORKGROUP / 2;
  PipelineDesc other_name = desc;
  other_name.shader = "voxel_loss (another kernel's)";
  const SharedPipeline a = shared_pipeline(ctx(), other_constant), b = shared_pipeline(ctx(), other_name);
  EXPECT_NE(a.get(), got[0].get());
  EXPECT_NE(b.get(), got[0].get());
  EXPECT_NE(a.get(), b.get());
  EXPECT_EQ(shared_pipeline(ctx(), other_constant).get(), a.get());
  PipelineDesc too_big = desc;
  too_big.workgroup_size = ctx().limits().maxComputeWorkGroupInvocations + 1;
  EXPECT_THROW(shared_pipeline(ctx(), too_big), std::runtime_error);
  EXPECT_THROW(shared_pipeline(ctx(), too_big), std::runtime_error);  // not kept as made
}

// Texel bindings: the kind must match the pipeline's, and a view must be aligned, inside its
// buffer and within maxTexelBufferElements; the assembly's pipeline has both kinds.
TEST_F(EngineTest, TexelBindingsCheckKindAlignmentAndRange) {
  PipelineDesc desc;
  desc.shader = "assemble_normal_equations";
  desc.spirv = shader_spirv(desc.shader);
  desc.binding_counts = {1, 1, 1, 1, 1, 1};
  desc.binding_kinds = {DescriptorKind::UniformTexelBuffer, DescriptorKind::UniformTexelBuffer,
                        DescriptorKind::UniformTexelBuffer, DescriptorKind::StorageBuffer,
                        DescriptorKind::UniformTexelBuffer, DescriptorKind::UniformTexelBuffer};
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  // Global accumulators: the shared ones are sized by a constant this test does not set.
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_VOXEL_WORKGROUP},
                                    {TFM_ASSEMBLE_SPEC_MODE, TFM_REDUCE_RUNS_GLOBAL}});
  desc.workgroup_size = TFM_VOXEL_WORKGROUP;
  ComputePipeline pipe(ctx(), desc);
  EXPECT_EQ(pipe.binding_kind(2), DescriptorKind::UniformTexelBuffer);
  EXPECT_EQ(pipe.binding_kind(3), DescriptorKind::StorageBuffer);
  EXPECT_EQ(pipe.binding_kind(9), DescriptorKind::StorageBuffer);
  const uint64_t align = ctx().limits().minTexelBufferOffsetAlignment;
  Buffer b(ctx(), 4 * align + 64, MemoryUsage::Device, "b");
  const VkFormat rgba = VK_FORMAT_R32G32B32A32_SFLOAT;
  const Binding t = Binding::texels(b, rgba, 0, 64);
  gpu::VoxelPairPush push{};
  push.opt_tf_size = push.ref_tf_size = 2;  // no voxels: only zero sums, which touch nothing
  CommandBatch batch(ctx());
  EXPECT_THROW(batch.dispatch(pipe, {t, t, b, b, t, t}, push, {1}), std::logic_error);  // storage as texels
  EXPECT_THROW(batch.dispatch(pipe, {t, t, t, t, t, t}, push, {1}), std::logic_error);  // texels as storage
  if (align > 1)
    EXPECT_THROW(batch.dispatch(pipe, {t, t, t, b, Binding::texels(b, rgba, align / 2, 64), t}, push, {1}),
                 std::logic_error);
  EXPECT_THROW(batch.dispatch(pipe, {t, t, t, b, Binding::texels(b, rgba, 4 * align, 128), t}, push, {1}),
               std::logic_error);  // past the end
  EXPECT_THROW(batch.dispatch(pipe, {t, t, t, b, Binding::texels(b, rgba, 0, 40), t}, push, {1}),
               std::logic_error);  // not whole texels
  // A valid set: nothing to read (voxel_count 0), views made and freed with the batch.
  batch.dispatch(pipe, {t, t, t, b, Binding::texels(b, rgba, align, 64), t}, push, {1});
  batch.submit_and_wait();
}

// An array of texel buffers (the renderer's field chunks) takes whole buffers, one view each.
TEST(PipelineDesc, TexelBindingKindsMarkTheNamedBindings) {
  const std::vector<DescriptorKind> kinds = texel_binding_kinds(4, {1, 3});
  const std::vector<DescriptorKind> expected = {DescriptorKind::StorageBuffer, DescriptorKind::UniformTexelBuffer,
                                                DescriptorKind::StorageBuffer, DescriptorKind::UniformTexelBuffer};
  EXPECT_EQ(kinds, expected);
  EXPECT_THROW(texel_binding_kinds(2, {2}), std::out_of_range);
}

TEST_F(EngineTest, TexelArraysTakeWholeBuffers) {
  PipelineDesc desc;
  desc.shader = "render_image";
  desc.spirv = shader_spirv(desc.shader);
  desc.binding_counts = gpu::to_vector(gpu::kRenderBindingCounts);
  desc.binding_kinds.assign(desc.binding_counts.size(), DescriptorKind::StorageBuffer);
  desc.binding_kinds[TFM_RENDER_BINDING_FIELD] = desc.binding_kinds[TFM_RENDER_BINDING_TF] =
      DescriptorKind::UniformTexelBuffer;
  desc.push_constant_bytes = sizeof(gpu::RenderPush);
  desc.workgroup_size = TFM_RENDER_TILE * TFM_RENDER_TILE;
  desc.specialization = gpu::render_specialization(1, TFM_RENDER_MODE_FORWARD);
  ComputePipeline pipe(ctx(), desc);
  Buffer b(ctx(), 1024, MemoryUsage::Device, "b");
  const std::vector<const Buffer*> chunks(TFM_RENDER_MAX_CHUNKS, &b);
  Binding offset = Binding::texels(chunks, VK_FORMAT_R32_SFLOAT);
  offset.texel_offset = ctx().limits().minTexelBufferOffsetAlignment;
  const Binding tf = Binding::texels(b, VK_FORMAT_R32G32B32A32_SFLOAT, 0, 64);
  gpu::RenderPush push{};
  CommandBatch batch(ctx());
  EXPECT_THROW(batch.dispatch(pipe, {offset, tf, b, b, b}, push, {1}), std::logic_error);
  EXPECT_THROW(batch.dispatch(pipe, {Binding::texels(std::vector<const Buffer*>(2, &b), VK_FORMAT_R32_SFLOAT), tf, b, b, b},
                              push, {1}),
               std::logic_error);  // fewer buffers than the array holds
  // A valid set, never submitted (no views are read): views made and freed with the batch.
  batch.dispatch(pipe, {Binding::texels(chunks, VK_FORMAT_R32_SFLOAT), tf, b, b, b}, push, {1});
}

TEST_F(EngineTest, SplitFieldChunksAndArrays) {
  std::vector<float> v(5000);
  std::iota(v.begin(), v.end(), 0.0f);
  DeviceField f(ctx(), v, "split", 1024);
  ASSERT_EQ(f.chunk_count(), 5u);
  EXPECT_EQ(f.chunk_size(4), 5000u - 4096u);
  std::vector<float> back(f.chunk_size(4));
  readback(ctx(), f.chunk(4), back.data(), back.size() * 4);
  EXPECT_EQ(back.front(), 4096.0f);
  EXPECT_EQ(back.back(), 4999.0f);
  auto arr = f.chunk_array(8);
  ASSERT_EQ(arr.size(), 8u);
  EXPECT_EQ(arr[7], &f.chunk(4));
  EXPECT_THROW(f.chunk_array(4), std::runtime_error);
}

TEST(VkCheck, NamesResultsAndThrows) {
  EXPECT_EQ(vk_result_name(VK_ERROR_DEVICE_LOST), "VK_ERROR_DEVICE_LOST");
  EXPECT_EQ(vk_result_name(VkResult(-12345)), "VkResult(-12345)");
  try {
    VK_CHECK(VK_ERROR_OUT_OF_DEVICE_MEMORY);
    FAIL() << "VK_CHECK did not throw";
  } catch (const VulkanError& e) {
    EXPECT_EQ(e.result(), VK_ERROR_OUT_OF_DEVICE_MEMORY);
    EXPECT_NE(std::string(e.what()).find("VK_ERROR_OUT_OF_DEVICE_MEMORY"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("test_engine.cpp"), std::string::npos);
  }
}

// A Context destroyed before a buffer made on it stops the program saying so (the buffer would
// free its memory on the destroyed device: a crash later, somewhere unrelated). A death test: the
// child process re-runs this test alone.
TEST(ContextDeathTest, DestroyedBeforeItsBuffersSaysSo) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        std::unique_ptr<Context> ctx = Context::create();
        static Buffer* kept = nullptr;  // outlives the context on purpose
        kept = new Buffer(*ctx, 256, MemoryUsage::Device, "kept");
        ctx.reset();
      },
      "a Context is destroyed while 1 buffers made on it");
  // In the right order, nothing is said.
  std::unique_ptr<Context> ctx = Context::create();
  { Buffer b(*ctx, 256, MemoryUsage::Device, "released first"); }
  EXPECT_NO_FATAL_FAILURE(ctx.reset());
}

TEST(DeviceSelection, BadSelectionsListTheDevices) {
  ContextOptions by_index;
  by_index.device_index = 999;
  try {
    Context::create(by_index);
    FAIL();
  } catch (const DeviceChoiceError& e) {
    EXPECT_NE(std::string(e.what()).find("out of range"), std::string::npos) << e.what();
  }
  ContextOptions by_name;
  by_name.device_name = "no-such-gpu-name";
  EXPECT_THROW(Context::create(by_name), DeviceChoiceError);
  // Selecting the first device by (a case-changed part of) its name works.
  auto devices = enumerate_devices();
  ASSERT_FALSE(devices.empty());
  ContextOptions ok;
  std::string part = devices[0].name.substr(0, 4);
  for (char& c : part) c = char(std::toupper(static_cast<unsigned char>(c)));
  ok.device_name = part;
  EXPECT_NO_THROW(Context::create(ok));
}

// An index is digits alone, and one past 2^32 - 1 is refused naming where it came from: taken
// modulo 2^32, "4294967296" chose device 0.
TEST(DeviceSelection, IndicesAreDigitsWithinThirtyTwoBits) {
  EXPECT_EQ(parse_device_index("0", "--device"), 0u);
  EXPECT_EQ(parse_device_index("007", "--device"), 7u);
  EXPECT_EQ(parse_device_index("4294967295", "--device"), 4294967295u);
  for (const std::string name : {"", "nvidia", "1.5", "-1", "0x0", " 1", "\xc3\xa9"})
    EXPECT_EQ(parse_device_index(name, "--device"), std::nullopt) << name;
  for (const std::string past : {"4294967296", "4294967297", "99999999999999999999999"}) {
    try {
      parse_device_index(past, "TFMATCH_DEVICE");
      ADD_FAILURE() << past << " was taken";
    } catch (const DeviceChoiceError& e) {
      EXPECT_NE(std::string(e.what()).find("TFMATCH_DEVICE: device index " + past + " is past"), std::string::npos)
          << e.what();
    }
  }
}

// The driver floor times a bare instance and device on the device Context::create chooses, and
// refuses a selection that fits none as Context::create does.
TEST(DriverFloor, TimesABareInstanceAndDeviceOfTheChosenDevice) {
  const DriverFloor floor = measure_driver_floor();
  const auto ctx = Context::create();
  EXPECT_EQ(floor.device, ctx->device_name());
  for (double ms : {floor.instance_ms, floor.device_ms, floor.teardown_ms}) {
    EXPECT_GT(ms, 0.0);
    EXPECT_LT(ms, 60000.0);
  }
  EXPECT_DOUBLE_EQ(floor.total_ms(), floor.instance_ms + floor.device_ms + floor.teardown_ms);
  ContextOptions bad;
  bad.device_index = 999;
  try {
    measure_driver_floor(bad);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("out of range"), std::string::npos) << e.what();
  }
}

TEST(Adoption, RejectsMissingHandles) {
  EXPECT_THROW(Context::adopt(ExternalDevice{}), std::invalid_argument);
}

}  // namespace
}  // namespace tfm

namespace tfm {
namespace {

// The checker the whole suite relies on: with the layer installed, a deliberately invalid call
// must produce a message (and take_validation_messages() then clears it).
TEST(Validation, CatchesAnInvalidCall) {
  Context& ctx = test::context();
  if (!ctx.validation_enabled()) {
    const char* env = std::getenv("TFMATCH_VALIDATION");
    if (env && std::string(env) == "1") FAIL() << "validation requested but not enabled (layer missing?)";
    GTEST_SKIP() << "validation layer not enabled in this run";
  }
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = 0;  // invalid: size must be greater than 0
  info.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
  VkBuffer buffer = VK_NULL_HANDLE;
  auto create = reinterpret_cast<PFN_vkCreateBuffer>(ctx.get_device_proc_addr()(ctx.device(), "vkCreateBuffer"));
  auto destroy = reinterpret_cast<PFN_vkDestroyBuffer>(ctx.get_device_proc_addr()(ctx.device(), "vkDestroyBuffer"));
  ASSERT_TRUE(create && destroy);
  VkResult r = create(ctx.device(), &info, nullptr, &buffer);
  if (r == VK_SUCCESS && buffer) destroy(ctx.device(), buffer, nullptr);
  auto messages = ctx.take_validation_messages();
  ASSERT_FALSE(messages.empty());
  EXPECT_NE(messages[0].find("size"), std::string::npos) << messages[0];
}

}  // namespace
}  // namespace tfm
