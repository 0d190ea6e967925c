// Double-precision CPU reference of DiffDVR's gradient: a straightforward reverse mode that
// marches each ray forward exactly as the CPU renderer does (host/reference/cpu_renderer.h), stores every
// sample, and walks the record backwards. The GPU backward pass (shaders/diffdvr_backward.comp)
// must agree with it to near float rounding.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/model/image_loss.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

struct CpuLossGradient {
  double loss = 0.0;                // sum over pixels and RGBA components
  std::vector<Rgba> gradient;       // dLoss/dT[j][c], one per TF entry
  std::vector<double> rgba;         // the rendered image X, 4 per pixel (as render_cpu)
  std::vector<uint32_t> stop;       // samples marched per pixel
  uint64_t samples = 0;
};

// The loss of the image of `volume` with `tf` from settings.camera against `target` (4 doubles
// per pixel, as render_cpu's rgba), and its gradient w.r.t. every TF entry. The TF's clamp to
// [0, 1] passes derivatives through (entries are kept in [0, 1]); samples whose optical depth
// is clamped (TFM_MAX_SAMPLE_OPTICAL_DEPTH) have no opacity derivative. Throws
// std::runtime_error for invalid settings, a TF with < 2 entries or a target of the wrong size.
CpuLossGradient image_loss_gradient_cpu(const Volume& volume, const TransferFunction& tf, const FieldRange& range,
                                        const RenderSettings& settings, std::span<const double> target,
                                        ImageLoss loss);

// The loss alone from two images (4 doubles per pixel).
double image_loss(std::span<const double> image, std::span<const double> target, ImageLoss loss);

}  // namespace tfm
