// Double-precision CPU reference of the visibility weights (kernels/visibility_weights.h,
// shaders/visibility_weights.comp): for each voxel x and camera v, T_v(x) = the product of
// tau = exp(-min(a depth_per_alpha, 20)) over the samples x + k dt u, k = 1 .. K + 1, u the unit
// direction from x's centre towards v's eye, s = t / dt (at most the renderer's max_steps), t the
// distance to where that segment leaves the box or reaches the eye, K = floor(s), the last
// sample's optical depth times s - K; trilinear with NaN samples empty; 0 below 2^-24 and outside
// v's view frustum. w(x) = the sum over the cameras of T_v(x)
// divided by its maximum over the voxels (unquantized: the GPU rounds to multiples of 2^-16).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "tfmatch/model/camera.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

struct CpuVisibilityWeights {
  std::vector<double> weights;     // w(x) per voxel, in [0, 1]
  double max_sum = 0.0;            // the largest sum before the division
  std::vector<uint8_t> ambiguous;  // with track_ambiguity: per voxel, 1 where a float marcher may
                                   // decide otherwise (a sample within `tolerance` of where its
                                   // NaN status changes, e.g. on a cell face of an axis-aligned view)
};

// Throws std::runtime_error for invalid settings, std::invalid_argument for no cameras.
CpuVisibilityWeights visibility_weights_cpu(const Volume& reference, const TransferFunction& tf,
                                            const FieldRange& range, const RenderSettings& settings,
                                            std::span<const OrbitCamera> cameras, bool track_ambiguity = false,
                                            double tolerance = 1e-4);

}  // namespace tfm
