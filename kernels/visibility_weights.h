// Wrapper of shaders/visibility_weights.comp: per-voxel visibility weights for the weighted voxel
// least squares (`--weights visibility`). The weight of voxel x is
//   w(x) = sum over the cameras v of T_v(x) / max over the voxels of the same sum,
// T_v(x) the transmittance of what lies in front of x seen from v's eye under the reference field
// and TF, sampled every step dt of the renderer's optical model from x towards the eye (0 outside
// v's view frustum; shaders/visibility_weights.comp states it exactly), quantized to multiples of 2^-16 (round(2^16 w) 2^-16, exact floats in [0, 1]). The assembly
// multiplies each voxel's terms by it (AssembleNormalEquationsKernel::record with weights), so
// the least squares care about the voxels as much as the reference renderings show them. The
// double-precision CPU reference is visibility_weights_cpu (host/reference).
#pragma once

#include <cstdint>
#include <memory>
#include <span>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/render_settings.h"

namespace tfm {

class Context;

struct VisibilityWeights {
  DeviceField weights;   // float32, chunked as the reference field
  double max_sum = 0.0;  // the largest sum of transmittances
  double gpu_ms = -1.0;  // -1 without timestamps
};

class VisibilityWeightsKernel {
 public:
  // For reference fields of `field_chunks` chunks (1..TFM_RENDER_MAX_CHUNKS).
  VisibilityWeightsKernel(Context& ctx, uint32_t field_chunks);
  ~VisibilityWeightsKernel();

  // The weights of `ref` (through `ref_map` and the TF table `ref_tf`) over `cameras`, with the
  // optical model of `settings` (step, opacity scale, termination; width and height give the
  // frustum's aspect). Throws std::invalid_argument for no cameras or a field whose chunking
  // does not fit, std::runtime_error when no voxel is in any camera's view. Rays longer than one
  // invocation may loop (llvmpipe) are marched one view at a time in parts (march_parts), with
  // the same bits; `max_part_samples` > 0 makes parts of at most that many samples on any device
  // (tests).
  VisibilityWeights compute(const DeviceField& ref, const VolumeGeometry& geometry, const FieldMapping& ref_map,
                            const Buffer& ref_tf, const RenderSettings& settings, std::span<const OrbitCamera> cameras,
                            uint32_t max_part_samples = 0) const;

 private:
  Context& ctx_;
  uint32_t chunks_;
  SharedPipeline sum_, quantize_;
};

}  // namespace tfm
