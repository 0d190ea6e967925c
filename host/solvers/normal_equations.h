// The host solver of the voxel least-squares system (host/model/normal_equations_system.h): tridiagonal
// LDL^T, or the minimum-norm solution when M is singular, ridge and smoothness regularization,
// cond(M); all O(N) in time and memory (host/solvers/tridiagonal.h).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/normal_equations_system.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/solvers/tridiagonal.h"

namespace tfm {

// Auto: LDL^T that decides the rank entry by entry (solve_psd_tridiagonal_min_norm): plain LDL^T
// when M has full rank, else the minimum-norm least-squares solution. LDLT: no rank decision (a
// singular M then falls back to Auto, with a warning).
enum class Factorization { Auto, LDLT };

struct SolveOptions {
  // Both are relative to the mean diagonal of M (voxels per TF entry), so a value means the
  // same for any volume size: ridge adds ridge*mean(diag) I, smooth adds smooth*mean(diag) D^T D.
  double ridge = 0.0;
  double smooth = 0.0;
  Factorization factorization = Factorization::Auto;
  // cond(M) above which the result is flagged as unreliable (see condition_warning_threshold()).
  double cond_warning = 1e4;
  // The system was assembled slab by slab: advice that names cgls (which reads the fields) says
  // it needs them in memory, in one process.
  bool streamed = false;
};

// Absolute weights of the regularization R = ridge I + smooth D^T D (D: first differences),
// i.e. SolveOptions' relative weights times mean(diag M). Every solver minimizes
// ||S x - b||^2 + x^T R x per channel with these.
struct Regularization {
  double ridge = 0.0;
  double smooth = 0.0;
};

// The largest relative smoothness weight. Under s D^T D the data decide only the constant part
// of x, through pivots that are differences of numbers s times their size, so x carries about
// 2e-17 s of double rounding (measured: 1.8e-4 at s = 1e13, below the data's float32 error up to
// s = 1e10). At 1e9 x is the mean reference colour, the limit of any heavier smoothing, to ~1e-7
// per entry already.
constexpr double kMaxRelativeSmooth = 1e9;

// The largest relative ridge weight. A ridge only shrinks x towards 0, without cancellation, so
// any weight is resolved; but times M's diagonal a weight near double's range overflows M + R
// (--ridge 1e307 failed as "tridiagonal eigenvalues: non-finite entries"). At 1e100 x is below
// 1e-100 of the colours: zero to any precision that matters.
constexpr double kMaxRelativeRidge = 1e100;

// How far a clamp to [0,1] must move a TF component for solve_normal_equations to warn: far
// below an 8-bit step (1/255), far above rounding (a TF's zeros fitted exactly land on -1e-9).
constexpr double kClampWarnDistance = 1e-4;

// Throws std::invalid_argument, naming the flag, for a weight that is negative, not finite, or
// above kMaxRelativeSmooth (smooth) or kMaxRelativeRidge (ridge).
Regularization absolute_regularization(const NormalEquations& eq, const SolveOptions& options);

// M + R.
Tridiagonal regularized_matrix(const NormalEquations& eq, const Regularization& r);

struct SolveResult {
  TransferFunction tf;                             // clamped to [0,1]
  Eigen::Matrix<double, Eigen::Dynamic, 4> x;      // unclamped least-squares solution
  std::string factorization;                       // "ldlt", or "min-norm-ldlt" when M is rank deficient
  double cond = 0.0;                               // of the regularized M (inf when singular)
  double lambda_min = 0.0, lambda_max = 0.0;       // of the regularized M
  // How much M's float32 error (~1e-7 relative) can grow in x: lambda_max(M) / lambda_min(M + R),
  // since ||dx|| <= ||dM|| ||x|| / lambda_min(M + R). It is cond when nothing is regularized; the
  // regularization R is exact, so a heavy smoothness term raises cond without making x uncertain.
  double error_amplification = 0.0;
  uint32_t unreferenced_entries = 0;               // TF entries no voxel touches (zero row of M)
  uint32_t dependent_entries = 0;                  // entries the data determine only together with
                                                   // their neighbours (solve_psd_tridiagonal_min_norm)
  uint32_t clamped_values = 0;                     // components moved into [0,1]
  std::vector<std::string> warnings;
};

// Solves (M + regularization) x = S^T b for the four channels at once, in O(N) time and memory
// for any N: entries no voxel touches get 0, and when M is singular x is its minimum-norm
// least-squares solution. Throws std::runtime_error if no voxel has data.
SolveResult solve_normal_equations(const NormalEquations& eq, const SolveOptions& options = {});

}  // namespace tfm
