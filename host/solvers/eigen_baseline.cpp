// Explicit sparse A and its normal equations with Eigen (the paper's CPU baseline).
#include "tfmatch/solvers/eigen_baseline.h"

#include <algorithm>
#include <stdexcept>
#include <vector>

#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {

ExplicitSystem build_explicit_system(std::span<const float> ref, std::span<const float> opt,
                                     const FieldMapping& ref_map, const FieldMapping& opt_map,
                                     const TransferFunction& ref_tf) {
  if (ref.size() != opt.size()) throw std::invalid_argument("build_explicit_system: size mismatch");
  const uint32_t n = opt_map.tf_size;
  std::vector<float> tf = ref_tf.as_floats();
  // First pass: which voxels have data, so A is allocated once at its final size.
  std::vector<uint8_t> keep(ref.size());
  size_t rows_voxels = 0;
  for (size_t i = 0; i < ref.size(); ++i) {
    keep[i] = !no_data(ref[i]) && !no_data(opt[i]);
    rows_voxels += keep[i];
  }
  // The explicit A (8 non-zeros a voxel, a double and an index each, and as much again while Eigen
  // fills and compresses it) and b: the paper's baseline is meant to be large, but a field the
  // budget cannot hold that way is said here, not met by the OOM killer (5.7 GiB at 150 MiB).
  check_memory(uint64_t(rows_voxels) * (2 * 8 * 12 + 4 * 8),
               "the explicit sparse A of " + std::to_string(rows_voxels) + " voxels (Eigen baseline solvers)");
  ExplicitSystem sys;
  sys.a.resize(Eigen::Index(4 * rows_voxels), Eigen::Index(4 * n));
  sys.a.reserve(Eigen::VectorXi::Constant(Eigen::Index(4 * rows_voxels), 2));
  sys.b.resize(Eigen::Index(4 * rows_voxels));
  size_t row = 0;
  for (size_t i = 0; i < ref.size(); ++i) {
    if ((i & 0xfffff) == 0) checkpoint("solve");
    if (!keep[i]) continue;
    uint32_t jr = 0, jo = 0;
    float wr = 0.0f, wo = 0.0f;
    tf_coordinate(ref[i], ref_map, jr, wr);
    tf_coordinate(opt[i], opt_map, jo, wo);
    for (int c = 0; c < 4; ++c) {
      const Eigen::Index r = Eigen::Index(4 * row + c);
      sys.a.insert(r, Eigen::Index(4 * jo + c)) = 1.0 - double(wo);
      sys.a.insert(r, Eigen::Index(4 * (jo + 1) + c)) = double(wo);
      double b = (1.0 - double(wr)) * tf[4 * jr + c] + double(wr) * tf[4 * (jr + 1) + c];
      sys.b(r) = std::clamp(b, 0.0, 1.0);
    }
    ++row;
  }
  sys.a.makeCompressed();
  return sys;
}

ExplicitNormalEquations explicit_normal_equations(const ExplicitSystem& s) {
  ExplicitNormalEquations ne;
  check_memory(uint64_t(s.a.nonZeros()) * 12 + uint64_t(s.a.rows()) * 4, "the transpose of the explicit sparse A");
  Eigen::SparseMatrix<double> at = s.a.transpose();
  ne.ata = (at * s.a).pruned();
  ne.atb = at * s.b;
  return ne;
}

NormalEquations to_tridiagonal(const ExplicitNormalEquations& ne, uint32_t n) {
  if (ne.ata.rows() != Eigen::Index(4 * n)) throw std::invalid_argument("to_tridiagonal: size mismatch");
  NormalEquations eq(n);
  // Channel 0 of the Kronecker structure; the other channels repeat it.
  for (uint32_t j = 0; j < n; ++j) eq.diag[j] = ne.ata.coeff(4 * j, 4 * j);
  for (uint32_t j = 0; j + 1 < n; ++j) eq.off[j] = ne.ata.coeff(4 * j, 4 * (j + 1));
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) eq.rhs(j, c) = ne.atb(4 * j + c);
  return eq;
}

}  // namespace tfm
