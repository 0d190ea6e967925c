// A device that cannot read unorm16 fields. Vulkan makes uniform texel buffers mandatory for the
// one- and four-voxel texel formats of float32, float16 and unorm8, but not for R16_UNORM or
// R16G16B16A16_UNORM; lavapipe has them, so the host here hands tfmatch a vkGetInstanceProcAddr
// whose vkGetPhysicalDeviceFormatProperties reports them without that feature, as such a device
// would. A unorm16 field must be refused where it enters, naming the device, the texel format it
// lacks and the formats it reads, before anything is recorded; the other formats still work.
#include "host_device.h"
#include "recording_host.h"
#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/recording.h"

#include <vulkan/vulkan.h>  // after tfmatch's headers: the loader's prototypes are still declared

#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace tfm {
namespace {

PFN_vkGetPhysicalDeviceFormatProperties real_format_properties = nullptr;
int format_queries = 0;

bool lacks_texel_reads(VkFormat format) {
  return format == VK_FORMAT_R16_UNORM || format == VK_FORMAT_R16G16B16A16_UNORM;
}

VKAPI_ATTR void VKAPI_CALL format_properties_without_unorm16(VkPhysicalDevice physical, VkFormat format,
                                                             VkFormatProperties* props) {
  ++format_queries;
  real_format_properties(physical, format, props);
  if (lacks_texel_reads(format)) props->bufferFeatures &= ~VkFormatFeatureFlags(VK_FORMAT_FEATURE_UNIFORM_TEXEL_BUFFER_BIT);
}

VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL host_get_instance_proc_addr(VkInstance instance, const char* name) {
  const PFN_vkVoidFunction found = vkGetInstanceProcAddr(instance, name);
  if (std::strcmp(name, "vkGetPhysicalDeviceFormatProperties") == 0) {
    real_format_properties = reinterpret_cast<PFN_vkGetPhysicalDeviceFormatProperties>(found);
    return reinterpret_cast<PFN_vkVoidFunction>(&format_properties_without_unorm16);
  }
  return found;
}

// The message of what `f` throws as UnsupportedFieldFormat ("" and a failure when it does not).
template <class F>
std::string refusal(F&& f) {
  try {
    f();
  } catch (const UnsupportedFieldFormat& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "another error: " << e.what();
    return {};
  }
  ADD_FAILURE() << "nothing was refused";
  return {};
}

TEST(EmbeddingFormatSupport, Unorm16FieldsAreRefusedWhereTheDeviceCannotReadThem) {
  test::HostDevice device;
  ASSERT_NO_FATAL_FAILURE(device.create());
  {
    std::unique_ptr<Context> ctx = Context::adopt(device.external(&host_get_instance_proc_addr));
    format_queries = 0;
    EXPECT_NE(field_format_unsupported(*ctx, FieldFormat::Unorm16).find("R16_UNORM"), std::string::npos);
    EXPECT_NE(field_format_unsupported(*ctx, FieldFormat::Unorm16, /*quads=*/false).find("R16_UNORM"),
              std::string::npos);
    for (FieldFormat format : {FieldFormat::Float32, FieldFormat::Float16, FieldFormat::Unorm8})
      EXPECT_EQ(field_format_unsupported(*ctx, format), "") << field_format_name(format);
    EXPECT_GT(format_queries, 0) << "the format's support was not asked of the host's function";
    // Asked once per format: dispatches that bind texels ask again and again.
    const int asked = format_queries;
    for (FieldFormat format : {FieldFormat::Float32, FieldFormat::Float16, FieldFormat::Unorm16, FieldFormat::Unorm8})
      (void)field_format_unsupported(*ctx, format);
    EXPECT_EQ(format_queries, asked) << "the driver was asked again for formats it had answered";

    Buffer memory(*ctx, 4096, MemoryUsage::Device, "host's volume buffer");
    const std::string adopt = refusal([&] {
      DeviceField::adopt(*ctx, memory.handle(), memory.offset(), 1000, "temperature", 0, FieldFormat::Unorm16);
    });
    const std::string device_name = ctx->device_name();
    for (const std::string& part : {std::string("temperature"), std::string("unorm16"), std::string("R16_UNORM"),
                                    device_name, std::string("float32, float16, unorm8")})
      EXPECT_NE(adopt.find(part), std::string::npos) << "'" << part << "' missing from: " << adopt;
    // Every other format is taken from the same buffer.
    for (FieldFormat format : {FieldFormat::Float32, FieldFormat::Float16, FieldFormat::Unorm8})
      EXPECT_NO_THROW(DeviceField::adopt(*ctx, memory.handle(), memory.offset(), 1000, "t", 0, format));

    EXPECT_NE(refusal([&] { ImageFieldRecorder copy(*ctx, {10, 10, 10}, VK_FORMAT_R16_UNORM, "volume image"); })
                  .find("R16_UNORM"),
              std::string::npos);
    EXPECT_NO_THROW(ImageFieldRecorder(*ctx, {10, 10, 10}, VK_FORMAT_R16_SFLOAT, "volume image"));

    // A unorm16 ensemble is refused before its recording starts; its float16 twin records.
    test::Host host(device);
    CorrelationRecorder correlation(*ctx);
    Buffer ensemble(*ctx, 4 * 64 * 2, MemoryUsage::Device, "ensemble"), out(*ctx, 64 * 4, MemoryUsage::Device, "field");
    const std::vector<float> series{0.1f, 0.4f, 0.2f, 0.9f};
    CorrelationParams params;
    VkCommandBuffer cmd = host.begin();
    const std::string ens = refusal(
        [&] { correlation.record_correlation(cmd, ensemble, FieldFormat::Unorm16, 64, series, params, out); });
    EXPECT_NE(ens.find("ensemble"), std::string::npos) << ens;
    EXPECT_NE(ens.find("R16_UNORM"), std::string::npos) << ens;
    EXPECT_NO_THROW(correlation.record_correlation(cmd, ensemble, FieldFormat::Float16, 64, series, params, out));
    host.submit_and_wait();
  }
  EXPECT_EQ(device.wait_idle(), VK_SUCCESS);
  for (const auto& m : device.messages()) ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace tfm
