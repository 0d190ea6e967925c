// Double-precision CPU reference of the GPU renderer (shaders/raymarch.glsl): the same rays,
// sample positions t_k = t_entry + (k + 0.5) dt, trilinear sampling with NaN as empty,
// node-aligned TF, alpha = 1 - exp(-a depth_per_alpha) and early termination.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "tfmatch/model/camera.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

struct CpuRenderOptions {
  // Rows [row_begin, row_end) are rendered; others stay empty (benchmarks time a band).
  uint32_t row_begin = 0;
  uint32_t row_end = std::numeric_limits<uint32_t>::max();
  // Flag pixels where a float renderer may legitimately take a different discrete decision:
  // sample count at a half-integer, transmittance at the stop threshold, or a sample at a cell
  // face where the NaN status of the corners changes. Costs extra samples when on.
  bool track_ambiguity = false;
  double ambiguity_tolerance = 1e-4;
  std::function<void(uint32_t rows_done)> progress;  // called after each row
};

struct CpuRender {
  uint32_t width = 0, height = 0;
  std::vector<double> rgba;         // premultiplied RGB and opacity, 4 per pixel
  std::vector<uint32_t> stop;       // samples marched per pixel
  std::vector<uint8_t> ambiguous;   // per pixel when tracked, else empty
  uint64_t samples = 0;             // sum of stop over the rendered rows
};

// Throws std::runtime_error for invalid settings or a TF with fewer than 2 entries.
CpuRender render_cpu(const Volume& volume, const TransferFunction& tf, const FieldRange& range,
                     const RenderSettings& settings, const CpuRenderOptions& options = {});

// The TF of DESIGN.md in double, each channel clamped to [0, 1]: x = clamp((v - lo) / (hi - lo),
// 0, 1) (N - 1), linear between entries floor(x) and floor(x) + 1.
Rgba classify_cpu(const TransferFunction& tf, const FieldRange& range, double v);

// Trilinear sample at index-space point p (clamped to the edge voxels); false when any corner
// is NaN.
bool sample_trilinear(const Volume& volume, const glm::dvec3& p, double& value);
// Whether moving p by +-eps along an axis changes whether its sample is empty (a NaN corner):
// where a float marcher may legitimately decide otherwise.
bool nan_status_ambiguous(const Volume& volume, const glm::dvec3& p, double eps);

}  // namespace tfm
