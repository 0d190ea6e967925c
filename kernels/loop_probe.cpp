// Pipeline and single dispatch of the loop probe.
#include "tfmatch/kernels/loop_probe.h"

#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/shaders/loop_probe_layout.h"
#include "tfmatch/shaders/shader_registry.h"

namespace tfm {

static_assert(sizeof(gpu::LoopProbePush) == 4, "LoopProbePush must match the GLSL push-constant block");

namespace {
// Bindings in the order the dispatch lists its buffers.
constexpr auto kBindingCounts = gpu::binding_counts({TFM_LOOP_PROBE_BINDING_VALUES, TFM_LOOP_PROBE_BINDING_TAKEN});
}  // namespace

uint32_t probe_loop_iterations(Context& ctx, uint32_t iterations) {
  PipelineDesc desc;
  desc.shader = "loop_probe";
  desc.binding_counts = gpu::to_vector(kBindingCounts);
  desc.push_constant_bytes = sizeof(gpu::LoopProbePush);
  desc.workgroup_size = 1;
  desc.spirv = shader_spirv(desc.shader);
  const SharedPipeline pipeline = shared_pipeline(ctx, desc);
  const std::vector<float> values(TFM_LOOP_PROBE_VALUES, 1.0f);
  const Buffer values_buffer = make_buffer<float>(ctx, values, "loop probe values");
  Buffer taken(ctx, 4, MemoryUsage::Device, "loop probe steps");
  gpu::LoopProbePush push{};
  push.iterations = iterations;
  CommandBatch batch(ctx);
  batch.dispatch(*pipeline, {values_buffer, taken}, push, {1});
  batch.submit_and_wait();
  uint32_t steps = 0;
  readback(ctx, taken, &steps, sizeof(steps));
  return steps;
}

}  // namespace tfm
