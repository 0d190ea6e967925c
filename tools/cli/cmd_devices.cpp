// `tfmatch devices`: the Vulkan devices and the features tfmatch uses.
#include <iomanip>
#include <iostream>

#include "cli.h"

namespace tfm::cli {
namespace {

int run_devices() {
  auto devices = enumerate_devices();
  if (devices.empty()) {
    std::cout << "no Vulkan devices (install mesa-vulkan-drivers for the lavapipe CPU device)\n";
    return 1;
  }
  for (const DeviceSummary& d : devices) {
    std::cout << "[" << d.index << "] " << d.name << " (" << d.type << ")\n"
              << "    driver: " << d.driver << ", Vulkan " << VK_API_VERSION_MAJOR(d.api_version) << "."
              << VK_API_VERSION_MINOR(d.api_version) << "." << VK_API_VERSION_PATCH(d.api_version) << "\n"
              << "    compute queue: " << (d.compute_queue ? "yes" : "no")
              << ", timestamps: " << (d.timestamps ? "yes" : "no") << ", shaderFloat64: "
              << (d.shader_float64 ? "yes" : "no") << "\n"
              << "    maxStorageBufferRange: " << d.max_storage_buffer_range / (1 << 20) << " MiB"
              << ", shared memory: " << d.max_shared_memory_bytes / 1024 << " KiB"
              << ", workgroup: " << d.max_workgroup_invocations << ", subgroup: " << d.subgroup_size << "\n"
              << "    device-local memory: " << std::fixed << std::setprecision(1)
              << double(d.device_local_bytes) / double(1ull << 30) << " GiB\n";
  }
  return 0;
}

CommandRegistration reg(90, [](CLI::App& app) {
  auto* sub = app.add_subcommand("devices", "List Vulkan devices with the features tfmatch uses");
  sub->callback([] { exit_code() = run_devices(); });
});

}  // namespace
}  // namespace tfm::cli
