// The decoded normal equations: from fixed-point slots, dense M, and the residual from the system alone.
#include "tfmatch/model/normal_equations_system.h"

#include <algorithm>
#include <stdexcept>

#include "tfmatch/shaders/shared_layout.h"  // TFM_ASSEMBLE_SLOTS

namespace tfm {

NormalEquations::NormalEquations(uint32_t n_) : n(n_), diag(n_, 0.0), off(n_ ? n_ - 1 : 0, 0.0), rhs(n_, 4) {
  rhs.setZero();
}

NormalEquations NormalEquations::from_slots(uint32_t n, std::span<const double> s, bool with_before) {
  if (s.size() < TFM_ASSEMBLE_SLOTS(n)) throw std::invalid_argument("NormalEquations::from_slots: too few slots");
  NormalEquations eq(n);
  for (uint32_t j = 0; j < n; ++j) eq.diag[j] = s[j];
  for (uint32_t j = 0; j + 1 < n; ++j) eq.off[j] = s[n + j];
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) eq.rhs(j, c) = s[2 * n - 1 + 4 * j + c];
  for (int c = 0; c < 4; ++c) eq.btb[c] = s[6 * n - 1 + c];
  eq.voxels = static_cast<uint64_t>(std::llround(s[6 * n + 3]));
  if (with_before) eq.before = std::array<double, 4>{s[6 * n + 4], s[6 * n + 5], s[6 * n + 6], s[6 * n + 7]};
  return eq;
}

Eigen::MatrixXd NormalEquations::dense_m() const {
  Eigen::MatrixXd m = Eigen::MatrixXd::Zero(n, n);
  for (uint32_t j = 0; j < n; ++j) m(j, j) = diag[j];
  for (uint32_t j = 0; j + 1 < n; ++j) m(j, j + 1) = m(j + 1, j) = off[j];
  return m;
}

std::array<double, 4> NormalEquations::residual_squared_per_channel(
    const Eigen::Matrix<double, Eigen::Dynamic, 4>& x) const {
  // ||Sx - b||^2 = x^T M x - 2 x^T S^T b + b^T b per channel.
  std::array<double, 4> out{};
  for (int c = 0; c < 4; ++c) {
    double xmx = 0.0;
    for (uint32_t j = 0; j < n; ++j) {
      xmx += diag[j] * x(j, c) * x(j, c);
      if (j + 1 < n) xmx += 2.0 * off[j] * x(j, c) * x(j + 1, c);
    }
    out[size_t(c)] = std::max(xmx - 2.0 * x.col(c).dot(rhs.col(c)) + btb[c], 0.0);
  }
  return out;
}

double NormalEquations::residual_squared(const Eigen::Matrix<double, Eigen::Dynamic, 4>& x) const {
  const std::array<double, 4> per_channel = residual_squared_per_channel(x);
  return std::max(per_channel[0] + per_channel[1] + per_channel[2] + per_channel[3], 0.0);
}

}  // namespace tfm
