// The image losses of DiffDVR as data (GPU-free: the kernels in kernels/diffdvr.h and the CPU
// reference in host/reference/diffdvr_cpu.h take them).
#pragma once

#include <cstdint>
#include <string>

namespace tfm {

// Per-pixel image loss over RGBA X = (premultiplied colour, opacity) against a target R.
enum class ImageLoss : uint32_t {
  L2 = 0,  // sum of (X - R)^2
  L1 = 1,  // sum of |X - R| (derivative sign(X - R), 0 where equal)
};
// "l2" or "l1"; throws std::runtime_error naming the value otherwise.
ImageLoss parse_image_loss(const std::string& name);
const char* image_loss_name(ImageLoss loss);

}  // namespace tfm
