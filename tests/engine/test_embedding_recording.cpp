// A renderer-like host that keeps its volumes in its own device buffer and re-fits a TF inside its
// own command buffers (kernels/recording.h): tfmatch reads the host's buffer in place, records
// into the host's command buffer and never submits; the host submits, waits on its fence, reads
// the O(N) result, solves and records the TF's upload into its own buffer and 1D images. The
// validation layer with synchronization validation watches the host's command buffers.
#include <vulkan/vulkan.h>  // the loader's prototypes first, as such a host includes them

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include <glm/gtc/packing.hpp>
#include <gtest/gtest.h>

#include "recording_host.h"
#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/recording.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {
namespace {

using test::EmbeddingRecording;
using test::Host;
using test::make_fields;
using test::reference_tf;

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
        // And the texels decode to the fitted TF within their format's rounding, so the encoding
        // both sides share is checked on its own: half floats to half an ulp (2^-11 relative,
        // 2^-25 absolute below 2^-14), unorm8 to half a step.
        for (size_t i = 0; i < fitted.size(); ++i) {
          const float x = fitted[i];
          double decoded = 0.0, bound = 0.0;
          if (r.format == VK_FORMAT_R32G32B32A32_SFLOAT) {
            decoded = static_cast<const float*>(r.map)[i];
          } else if (r.format == VK_FORMAT_R16G16B16A16_SFLOAT) {
            decoded = glm::unpackHalf1x16(static_cast<const uint16_t*>(r.map)[i]);
            bound = std::max(std::ldexp(std::abs(double(x)), -11), std::ldexp(1.0, -25));
          } else {
            decoded = static_cast<const uint8_t*>(r.map)[i] / 255.0;
            bound = 0.5 / 255.0 + 1e-9;
          }
          const double target = r.format == VK_FORMAT_R8G8B8A8_UNORM ? std::clamp(double(x), 0.0, 1.0) : double(x);
          EXPECT_LE(std::abs(decoded - target), bound) << "format " << int(r.format) << ", component " << i;
        }
        EXPECT_FALSE(fitted.empty());
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
    // The first recording over it is not measured: the driver may build the pipeline variant this
    // size takes only now (lavapipe compiles at the first dispatch, and on the run after its shader
    // cache was filled, loading the variant from that cache grew the process by 30 MB).
    uint64_t grown = 0;
    for (int run = 0; run < 2; ++run) {
      const uint64_t before = resident_memory();
      VkCommandBuffer cmd = host.begin();
      recorder.record_assemble(cmd, big_ref, big_opt, rm, om, tf_floats);
      host.submit_and_wait();
      EXPECT_EQ(recorder.result().voxels, big);
      grown = resident_memory() - std::min(before, resident_memory());
    }
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
    // Past the end of the host's 64 KiB buffer (its memory requirement bounds its size).
    try {
      DeviceField::adopt(ctx, volume, 0, 1 << 16, "f");
      ADD_FAILURE() << "a field of 256 KiB over a buffer of 64 KiB was adopted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("pass the end of the buffer"), std::string::npos) << e.what();
    }
    // A host that does not say its instance's Vulkan version, or one below 1.2: refused, since
    // tfmatch's SPIR-V is for 1.2 (an instance made without VkApplicationInfo is 1.0).
    for (const uint32_t version : {0u, uint32_t(VK_API_VERSION_1_0), uint32_t(VK_API_VERSION_1_1)}) {
      ExternalDevice e = device_.external();
      e.api_version = version;
      try {
        Context::adopt(e);
        ADD_FAILURE() << "adopted with api_version " << version;
      } catch (const std::invalid_argument& error) {
        EXPECT_NE(std::string(error.what()).find("VK_API_VERSION_1_2"), std::string::npos) << error.what();
      }
    }
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
