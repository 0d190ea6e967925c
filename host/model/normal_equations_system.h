// The voxel least-squares system in its tridiagonal form (DESIGN.md): M = S^T S (2N-1 numbers),
// S^T b (N x 4), b^T b (4) and the voxel count, as the GPU assembly returns it (double precision).
#pragma once

#include <array>
#include <optional>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace tfm {

struct NormalEquations {
  uint32_t n = 0;
  std::vector<double> diag;             // M[j][j], j < n
  std::vector<double> off;              // M[j][j+1], j < n-1
  Eigen::Matrix<double, Eigen::Dynamic, 4> rhs;  // S^T b
  std::array<double, 4> btb{};         // sum of b_c^2 per channel
  uint64_t voxels = 0;                  // voxels with data in both fields
  // The loss before optimization when the reference TF has another size than n (the second field
  // mapped onto the reference TF's own entries): per channel sum of (T_r(F_o) - b)^2.
  std::optional<std::array<double, 4>> before;

  explicit NormalEquations(uint32_t n_ = 0);
  // From the fixed-point accumulators of assemble_normal_equations (TFM_ASSEMBLE_SLOTS layout);
  // `with_before`: the slots carry the before loss.
  static NormalEquations from_slots(uint32_t n, std::span<const double> slots, bool with_before = false);
  // ||S x - b||^2 summed over channels, from the system alone (x: n x 4).
  double residual_squared(const Eigen::Matrix<double, Eigen::Dynamic, 4>& x) const;
  // The same per channel (each clamped at 0 against rounding).
  std::array<double, 4> residual_squared_per_channel(const Eigen::Matrix<double, Eigen::Dynamic, 4>& x) const;
  Eigen::MatrixXd dense_m() const;
};

}  // namespace tfm
