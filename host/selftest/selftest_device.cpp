// Self-test cases of what the kernels assume of the device beyond its Vulkan limits: the loop
// probe (shaders/loop_probe.comp) against Context::loop_iteration_limit(), the loop limit every
// kernel with input-sized loops keeps within (docs/design.md). A driver that ends loops early where
// the engine expects none would let those kernels return silently wrong results; one that the
// engine believes limited but runs the loop whole only makes them refuse work they could do.
#include <algorithm>
#include <string>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/loop_probe.h"
#include "tfmatch/selftest/selftest_support.h"

namespace tfm::selftest {
namespace {

// A loop of `iterations` steps in one invocation: whole where the engine knows no limit, ended at
// exactly the known limit where it knows one (llvmpipe counts down from 65535 at the end of each
// iteration and leaves the loop at 0: a lone loop runs 65535 steps).
void loop_limit(Context& ctx, Check& check, uint32_t iterations) {
  const uint32_t steps = probe_loop_iterations(ctx, iterations);
  const uint32_t known = ctx.loop_iteration_limit();
  if (known == 0) {
    check.equal("loop steps taken (no limit known for this driver)", 0, steps, iterations);
    return;
  }
  check.equal("loop steps taken (the driver's known limit)", 0, steps, std::min(iterations, known));
}

}  // namespace

void add_device_cases(CaseList& cases) {
  // Below llvmpipe's 65535, and three times past it.
  for (const uint32_t iterations : {60000u, 200000u})
    cases.push_back({"loop_probe", "probe_loop_iterations",
                     "one invocation's loop of " + std::to_string(iterations) + " steps", true, 1,
                     [iterations](Context& ctx, Check& check) { loop_limit(ctx, check, iterations); }, 2});
}

}  // namespace tfm::selftest
