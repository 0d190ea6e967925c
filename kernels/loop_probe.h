// The loop probe (shaders/loop_probe.comp): how many iterations one shader invocation's loop runs
// on this device before the driver ends it. The self-test compares it with
// Context::loop_iteration_limit(), the limit every kernel with input-sized loops is checked against.
#pragma once

#include <cstdint>

namespace tfm {

class Context;

// Runs one invocation whose loop should take `iterations` steps and returns the steps it took:
// `iterations` on a device without a loop limit, fewer where the driver ends loops early.
uint32_t probe_loop_iterations(Context& ctx, uint32_t iterations);

}  // namespace tfm
