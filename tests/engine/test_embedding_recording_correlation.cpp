// Correlation fields recorded into a renderer-like host's command buffers (kernels/recording.h):
// ensembles in the host's buffer in every field format and as one 3D image per member, read on
// the device with the bits of CorrelationKernel::compute on the same numbers.
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
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/model/correlation_reference.h"

namespace tfm {
namespace {

using test::EmbeddingRecording;
using test::Host;
using test::member_value;

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
          values[m * voxels + v] = float(member_value(m, v));
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
            const double x = 0.5 + 0.35 * member_value(m, v);  // in [0.045, 0.955]
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

}  // namespace
}  // namespace tfm
