// Device buffers against the device's memory and the process's memory budget
// (host/model/memory_budget.h): checked before buffers whose size an input decides are made.
#pragma once

#include <cstdint>
#include <string>

namespace tfm {

class Context;

// For device buffers of `bytes` in all: throws std::runtime_error when they exceed the device's
// largest memory heap, and checks them against the budget too where device memory is the host's
// (CPU and integrated devices, lavapipe among them).
void check_device_memory(const Context& ctx, uint64_t bytes, const std::string& what);

// Whether the device's memory is the host's (CPU and integrated devices, lavapipe among them): its
// buffers count against the budget beside the host's own.
bool device_memory_is_host(const Context& ctx);

}  // namespace tfm
