// Device buffers against the device's memory and the process's memory budget
// (host/model/memory_budget.h): checked before buffers whose size an input decides are made.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "tfmatch/engine/device_field.h"

namespace tfm {

class Context;

// For device buffers of `bytes` in all: throws std::runtime_error when they exceed the device's
// largest memory heap, and checks them against the budget too where device memory is the host's
// (CPU and integrated devices, lavapipe among them).
void check_device_memory(const Context& ctx, uint64_t bytes, const std::string& what);

// A field over `values` in host memory: read where they are on a device that can
// (DeviceField::in_host_memory, DeviceField::reads_host_memory: nothing copied), else uploaded
// into device memory after check_device_memory names `what`. The caller keeps `values` alive and
// unchanged while the field is used.
DeviceField field_over_host_values(Context& ctx, std::span<const float> values, const std::string& what,
                                   uint64_t max_chunk_voxels = 0);

// Whether the device's memory is the host's (CPU and integrated devices, lavapipe among them): its
// buffers count against the budget beside the host's own.
bool device_memory_is_host(const Context& ctx);

}  // namespace tfm
