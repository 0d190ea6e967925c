// A Vulkan application that owns its instance, device and queue (plain loader, no volk), lends
// them to tfmatch, fits a transfer function on the GPU and checks it on the CPU. Exit code 0
// when the GPU system equals a plain double-precision sum and the fitted TF recovers the known
// answer; 1 otherwise; 2 when the machine has no Vulkan device with a compute queue.
#include <vulkan/vulkan.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include <tfmatch/engine/context.h>
#include <tfmatch/engine/device_field.h>
#include <tfmatch/model/field_mapping.h>
#include <tfmatch/kernels/gpu_voxel_ops.h>
#include <tfmatch/solvers/normal_equations.h>
#include <tfmatch/model/transfer_function.h>

namespace {

// The application's Vulkan objects, created and destroyed by the application.
struct App {
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t family = 0;

  bool create() {
    VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
    app.pApplicationName = "tfmatch embed example";
    app.apiVersion = VK_API_VERSION_1_2;
    VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
    info.pApplicationInfo = &app;
    if (vkCreateInstance(&info, nullptr, &instance) != VK_SUCCESS) return false;
    uint32_t count = 0;
    vkEnumeratePhysicalDevices(instance, &count, nullptr);
    std::vector<VkPhysicalDevice> devices(count);
    vkEnumeratePhysicalDevices(instance, &count, devices.data());
    for (VkPhysicalDevice pd : devices) {
      uint32_t n = 0;
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, nullptr);
      std::vector<VkQueueFamilyProperties> families(n);
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, families.data());
      for (uint32_t i = 0; i < n; ++i)
        if (families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) {
          physical = pd;
          family = i;
          break;
        }
      if (physical) break;
    }
    if (!physical) return false;
    const float priority = 1.0f;
    VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
    queue_info.queueFamilyIndex = family;
    queue_info.queueCount = 1;
    queue_info.pQueuePriorities = &priority;
    VkDeviceCreateInfo device_info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
    device_info.queueCreateInfoCount = 1;
    device_info.pQueueCreateInfos = &queue_info;
    if (vkCreateDevice(physical, &device_info, nullptr, &device) != VK_SUCCESS) return false;
    vkGetDeviceQueue(device, family, 0, &queue);
    return true;
  }

  ~App() {
    if (device) vkDestroyDevice(device, nullptr);
    if (instance) vkDestroyInstance(instance, nullptr);
  }
};

}  // namespace

int main() {
  App app;
  if (!app.create()) {
    std::fprintf(stderr, "no Vulkan device with a compute queue\n");
    return 2;
  }

  // A reference field and a second field that is its reversed copy in other units: the best TF
  // for the second field is the reference TF mirrored, and it reproduces the colours exactly.
  const uint32_t n = 16;
  std::vector<float> ref(5000), opt(5000);
  for (size_t i = 0; i < ref.size(); ++i) {
    ref[i] = float(i % 1000) / 999.0f;
    opt[i] = 300.0f - 40.0f * ref[i];  // kelvin, decreasing
  }
  tfm::TransferFunction ref_tf;
  for (uint32_t j = 0; j < n; ++j) {
    const double t = double(j) / (n - 1);
    ref_tf.rgba.push_back({t, 1.0 - t, 0.5 * t, 0.2 + 0.6 * t});
  }
  const tfm::FieldMapping ref_map = tfm::make_mapping({0.0, 1.0}, n);
  const tfm::FieldMapping opt_map = tfm::make_mapping({260.0, 300.0}, n);

  int failures = 0;
  try {
    // tfmatch borrows the handles: the application still owns and destroys them.
    tfm::ExternalDevice external{app.instance, app.physical, app.device, app.queue, app.family, nullptr};
    external.api_version = VK_API_VERSION_1_2;  // what the instance was created with
    auto ctx = tfm::Context::adopt(external);
    tfm::DeviceField ref_field(*ctx, ref, "reference"), opt_field(*ctx, opt, "second field");
    tfm::Buffer tf_buffer = tfm::upload_tf(*ctx, ref_tf, "reference TF");
    tfm::GpuNormalEquations gpu(*ctx, n);
    gpu.add(ref_field, opt_field, ref_map, opt_map, tf_buffer);
    const tfm::NormalEquations eq = gpu.result();

    // The same system summed on the CPU in double precision from the same float32 weights.
    std::vector<double> diag(n, 0.0);
    uint64_t voxels = 0;
    for (size_t i = 0; i < opt.size(); ++i) {
      uint32_t j;
      float w;
      if (!tfm::tf_coordinate(opt[i], opt_map, j, w)) continue;
      diag[j] += (1.0 - w) * (1.0 - w);
      diag[j + 1] += double(w) * w;
      ++voxels;
    }
    if (eq.voxels != voxels) ++failures, std::fprintf(stderr, "voxel count %llu, expected %llu\n",
                                                     (unsigned long long)eq.voxels, (unsigned long long)voxels);
    for (uint32_t j = 0; j < n; ++j)
      if (std::abs(eq.diag[j] - diag[j]) > 1e-6 * diag[j] + 1e-9)
        ++failures, std::fprintf(stderr, "M[%u][%u] = %.9g, CPU %.9g\n", j, j, eq.diag[j], diag[j]);

    const tfm::SolveResult solved = tfm::solve_normal_equations(eq);
    double worst = 0.0;
    for (uint32_t j = 0; j < n; ++j)
      for (int c = 0; c < 4; ++c) worst = std::max(worst, std::abs(solved.tf.rgba[j][c] - ref_tf.rgba[n - 1 - j][c]));
    std::printf("device: %s\nvoxels: %llu\nlargest |T_o[j] - T_r[N-1-j]|: %.2e\n", ctx->device_name().c_str(),
                (unsigned long long)eq.voxels, worst);
    if (worst > 1e-3) ++failures, std::fprintf(stderr, "the fitted TF is not the mirrored reference TF\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tfmatch: %s\n", e.what());
    return 1;
  }
  // The context is gone; the application's device is still its own and still works.
  if (vkDeviceWaitIdle(app.device) != VK_SUCCESS) ++failures;
  std::printf(failures ? "FAILED\n" : "OK\n");
  return failures ? 1 : 0;
}
