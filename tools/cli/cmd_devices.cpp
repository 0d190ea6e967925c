// `tfmatch devices`: the Vulkan devices and the features tfmatch uses, and whether the CUDA
// solvers can run (builds with TFMATCH_CUDA), as text or JSON.
#include <iomanip>
#include <iostream>
#include <optional>

#include "cli.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#ifdef TFMATCH_HAVE_CUDA
#include "tfmatch/cuda/cuda_backend.h"
#endif
#include "output_options.h"
#include "tfmatch/io/output_check.h"

namespace tfm::cli {
namespace {

// Names of the subgroup operation classes in `flags` (VkSubgroupFeatureFlags), space-separated.
std::vector<std::string> subgroup_operation_names(uint32_t flags) {
  const std::pair<uint32_t, const char*> names[] = {
      {VK_SUBGROUP_FEATURE_BASIC_BIT, "basic"},         {VK_SUBGROUP_FEATURE_VOTE_BIT, "vote"},
      {VK_SUBGROUP_FEATURE_ARITHMETIC_BIT, "arithmetic"}, {VK_SUBGROUP_FEATURE_BALLOT_BIT, "ballot"},
      {VK_SUBGROUP_FEATURE_SHUFFLE_BIT, "shuffle"},     {VK_SUBGROUP_FEATURE_SHUFFLE_RELATIVE_BIT, "shuffle_relative"},
      {VK_SUBGROUP_FEATURE_CLUSTERED_BIT, "clustered"}, {VK_SUBGROUP_FEATURE_QUAD_BIT, "quad"}};
  std::vector<std::string> out;
  for (const auto& [bit, name] : names)
    if (flags & bit) out.emplace_back(name);
  return out;
}

std::string version_string(uint32_t v) {
  return std::to_string(VK_API_VERSION_MAJOR(v)) + "." + std::to_string(VK_API_VERSION_MINOR(v)) + "." +
         std::to_string(VK_API_VERSION_PATCH(v));
}

// The text output's fields, in bytes where the text shows MiB, KiB or GiB.
nlohmann::json devices_json(const std::vector<DeviceSummary>& devices) {
  nlohmann::json list = nlohmann::json::array();
  for (const DeviceSummary& d : devices)
    list.push_back({{"index", d.index},
                    {"name", d.name},
                    {"type", d.type},
                    {"driver", d.driver},
                    {"vulkan", version_string(d.api_version)},
                    {"compute_queue", d.compute_queue},
                    {"timestamps", d.timestamps},
                    {"shader_float64", d.shader_float64},
                    {"int64_atomics", d.int64_atomics},
                    {"subgroup_operations", subgroup_operation_names(d.subgroup_operations)},
                    {"max_storage_buffer_range_bytes", d.max_storage_buffer_range},
                    {"max_shared_memory_bytes", d.max_shared_memory_bytes},
                    {"max_workgroup_invocations", d.max_workgroup_invocations},
                    {"subgroup_size", d.subgroup_size},
                    {"device_local_bytes", d.device_local_bytes}});
  return {{"devices", list}};
}

// The CUDA solvers: not built; or the plugin (host/solvers/cuda/cuda_backend.h) with the CUDA
// device it sees, or why they cannot run. Loading the plugin and asking the CUDA runtime for its
// devices happens here only, never in the commands that do not use them.
nlohmann::json cuda_json() {
#ifdef TFMATCH_HAVE_CUDA
  const cuda::PluginStatus& plugin = cuda::plugin_status();
  nlohmann::json out{{"built", true}, {"plugin", plugin.path}};
  std::string why;
  if (!plugin.backend)
    out["error"] = plugin.error;
  else if (plugin.backend->device_available(&why))
    out["device"] = plugin.backend->device_name();
  else
    out["error"] = "no CUDA device available (cudaGetDeviceCount: " + why + ")";
  return out;
#else
  return {{"built", false}};
#endif
}

void print_cuda(const nlohmann::json& cuda) {
  std::cout << "CUDA solvers: ";
  if (!cuda["built"].get<bool>())
    std::cout << "not in this build (TFMATCH_CUDA off)\n";
  else if (cuda.contains("device"))
    std::cout << cuda["device"].get<std::string>() << " (plugin " << cuda["plugin"].get<std::string>() << ")\n";
  else
    std::cout << "cannot run: " << cuda["error"].get<std::string>() << "\n";
}

void print_devices(const std::vector<DeviceSummary>& devices) {
  for (const DeviceSummary& d : devices) {
    std::cout << "[" << d.index << "] " << d.name << " (" << d.type << ")\n"
              << "    driver: " << d.driver << ", Vulkan " << version_string(d.api_version) << "\n"
              << "    compute queue: " << (d.compute_queue ? "yes" : "no")
              << ", timestamps: " << (d.timestamps ? "yes" : "no") << ", shaderFloat64: "
              << (d.shader_float64 ? "yes" : "no") << ", 64-bit atomics: " << (d.int64_atomics ? "yes" : "no")
              << "\n"
              << "    maxStorageBufferRange: " << d.max_storage_buffer_range / (1 << 20) << " MiB"
              << ", shared memory: " << d.max_shared_memory_bytes / 1024 << " KiB"
              << ", workgroup: " << d.max_workgroup_invocations << ", subgroup: " << d.subgroup_size << "\n"
              << "    subgroup operations:";
    for (const std::string& op : subgroup_operation_names(d.subgroup_operations)) std::cout << " " << op;
    std::cout << "\n"
              << "    device-local memory: " << std::fixed << std::setprecision(1)
              << double(d.device_local_bytes) / double(1ull << 30) << " GiB\n";
  }
}

// `json_target`: --json's value (empty: text only). `floor`: also time the driver alone
// (measure_driver_floor) on the device tfmatch would choose.
int run_devices(const std::string& json_target, bool floor) {
  const JsonOutput json(json_target);  // first: with '-', stdout holds only the JSON
  FilePlan().output(json.file(), "--json").check();
  auto devices = enumerate_devices();
  nlohmann::json out = devices_json(devices);
  std::optional<DriverFloor> measured;
  if (floor && !devices.empty()) {
    measured = measure_driver_floor(context_options());
    out["driver_floor"] = {{"device", measured->device},
                           {"instance_ms", measured->instance_ms},
                           {"device_ms", measured->device_ms},
                           {"teardown_ms", measured->teardown_ms},
                           {"total_ms", measured->total_ms()}};
  }
  out["cuda"] = cuda_json();
  json.write(out);
  if (devices.empty()) {
    std::cout << "no Vulkan devices (install mesa-vulkan-drivers for the lavapipe CPU device)\n";
  } else {
    print_devices(devices);
  }
  print_cuda(out["cuda"]);
  if (measured)
    std::cout << std::fixed << std::setprecision(1) << "driver floor on " << measured->device
              << ": instance " << measured->instance_ms << " ms + device " << measured->device_ms
              << " ms + teardown " << measured->teardown_ms << " ms = " << measured->total_ms() << " ms\n";
  return devices.empty() ? 1 : 0;
}

CommandRegistration reg(90, [](CLI::App& app) {
  auto json = std::make_shared<std::string>();
  auto floor = std::make_shared<bool>(false);
  auto* sub = app.add_subcommand("devices",
                                 "List Vulkan devices with the features tfmatch uses, and the CUDA device the CUDA "
                                 "solvers would use (or why they cannot run)");
  add_json_option(sub, *json, "the device list");
  sub->add_flag("--floor", *floor,
                "Also time what the driver alone costs a process on the device tfmatch would choose: a bare "
                "instance, that device with one queue and nothing enabled, and their teardown (the floor "
                "under tfmatch's start-up)");
  sub->callback([json, floor] { exit_code() = run_devices(*json, *floor); });
});

}  // namespace
}  // namespace tfm::cli
