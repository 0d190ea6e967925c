// Interface of shaders/loop_probe.comp, shared by GLSL and kernels/loop_probe.cpp: bindings and
// the push-constant block (4-byte scalars only, so std430 and C++ layouts coincide).
#ifndef TFMATCH_LOOP_PROBE_LAYOUT_H
#define TFMATCH_LOOP_PROBE_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
namespace tfm::gpu {
#endif

#define TFM_LOOP_PROBE_VALUES 64u           // floats the loop reads, all >= 0
#define TFM_LOOP_PROBE_BINDING_VALUES 0     // float[TFM_LOOP_PROBE_VALUES]
#define TFM_LOOP_PROBE_BINDING_TAKEN 1      // uint: the iterations the loop ran

#if defined(__cplusplus) || defined(TFM_WANT_LOOP_PROBE_PUSH)
TFM_PUSH_CONSTANTS(LoopProbePush) {
  uint iterations;  // the loop's trip count
} TFM_PUSH_INSTANCE(pc);
#endif

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif

#endif  // TFMATCH_LOOP_PROBE_LAYOUT_H
