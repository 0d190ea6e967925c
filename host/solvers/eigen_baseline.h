// The paper's CPU path: the explicit sparse system matrix A = S (x) I_4 (two non-zeros per row,
// 4 rows per voxel, stride 4 between a row's non-zeros) built with Eigen, and A^T A, A^T b from
// sparse products. It is the baseline the GPU assembly is measured against, and a solver.
#pragma once

#include <span>

#include <Eigen/SparseCore>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {

struct ExplicitSystem {
  Eigen::SparseMatrix<double, Eigen::RowMajor> a;  // (4 * voxels with data) x (4 N), CSR
  Eigen::VectorXd b;                               // reference colours, RGBA per voxel
};

// Builds A and b from the voxels that have data in both fields (NaN skipped), with the same
// float32 TF coordinates as the GPU kernels.
ExplicitSystem build_explicit_system(std::span<const float> ref, std::span<const float> opt,
                                     const FieldMapping& ref_map, const FieldMapping& opt_map,
                                     const TransferFunction& ref_tf);

// A^T A and A^T b by Eigen sparse products, as the paper's CPU normal-equations path does.
struct ExplicitNormalEquations {
  Eigen::SparseMatrix<double> ata;  // 4N x 4N, band at distance 0 and 4
  Eigen::VectorXd atb;              // 4N
};
ExplicitNormalEquations explicit_normal_equations(const ExplicitSystem& system);

// The same system in the tridiagonal form (M = block of A^T A for one channel).
NormalEquations to_tridiagonal(const ExplicitNormalEquations& ne, uint32_t n);

}  // namespace tfm
