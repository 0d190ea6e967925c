// How many loop iterations one invocation of this device runs before its driver ends the loop: a
// single loop of pc.iterations steps, each reading one of the values (all >= 0, so every step
// counts and no compiler can fold the loop away), counting the steps taken. llvmpipe (lavapipe)
// ends an invocation's loops after 65535 iterations in all, silently; the kernels check their worst
// cases against Context::loop_iteration_limit(), and the self-test checks that value against this
// count on every device.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_LOOP_PROBE_PUSH
#include "loop_probe_layout.h"

layout(local_size_x = 1) in;

layout(std430, binding = TFM_LOOP_PROBE_BINDING_VALUES) readonly buffer Values { float values[]; };
layout(std430, binding = TFM_LOOP_PROBE_BINDING_TAKEN) writeonly buffer Taken { uint taken; };

void main() {
  uint steps = 0u;
  for (uint i = 0u; i < pc.iterations; ++i) steps += values[i % TFM_LOOP_PROBE_VALUES] >= 0.0 ? 1u : 0u;
  taken = steps;
}
