// Volumes of a renderer-like host in every field format, in its buffers and its 3D images: every
// recorded kernel gives the bits of float32 arrays of the same values (kernels/recording.h).
#include <vulkan/vulkan.h>  // the loader's prototypes first, as such a host includes them

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>

#include <glm/gtc/packing.hpp>
#include <gtest/gtest.h>

#include "recording_host.h"
#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/gradient_descent.h"
#include "tfmatch/kernels/histogram.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {
namespace {

using test::EmbeddingRecording;
using test::Host;
using test::member_value;
using test::make_fields;
using test::reference_tf;

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
                                      extent, VK_FORMAT_R32_SFLOAT};
        const ImageFieldView opt_view{host.view_3d(image, vk_format), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, extent,
                                      vk_format};
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
        values[m * member_voxels + v] = float(member_value(m, v));
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

}  // namespace
}  // namespace tfm
