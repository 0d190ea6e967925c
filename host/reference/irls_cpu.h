// Double-precision CPU reference of the IRLS pass (shaders/irls_assemble.comp, kernels/irls.h):
// at a TF x and weight floors delta, per channel the weighted tridiagonal normal equations and
// the l1 loss, with the bound within which the kernel's float32 arithmetic must agree.
#pragma once

#include <array>
#include <span>
#include <vector>

#include "tfmatch/model/field_mapping.h"

namespace tfm {

struct IrlsPassCpu {
  // Channel c: sum over voxels of w (1-t)^2 into entry j and w t^2 into j + 1 (diag, n),
  // w (1-t) t into j (off, n - 1), w (1-t) b_c into j and w t b_c into j + 1 (rhs, n), with
  // w = delta_c / max(|e|, delta_c); l1: the sum of |e|.
  std::array<std::vector<double>, 4> diag, off, rhs;
  std::array<double, 4> l1{};
  // How far the kernel may be from each value: it forms e in float32 (within 1e-6 of the double
  // e for values in [0,1]), so w within w 1e-6 / max(|e|, delta); each term a few float
  // roundings (2^-22 relative) and truncated to 2^-32 on its own.
  std::array<std::vector<double>, 4> diag_bound, off_bound, rhs_bound;
  std::array<double, 4> l1_bound{};
};

// `ref_tf` and `x` as float RGBA entries (ref_map.tf_size and opt_map.tf_size of them); voxels
// without data in both fields add nothing. Throws std::invalid_argument when sizes disagree or a
// delta is not positive.
IrlsPassCpu irls_pass_cpu(std::span<const float> ref, std::span<const float> opt, const FieldMapping& ref_map,
                          const FieldMapping& opt_map, std::span<const float> ref_tf, std::span<const float> x,
                          const std::array<float, 4>& delta);

}  // namespace tfm
