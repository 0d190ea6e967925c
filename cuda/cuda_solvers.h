// Plain C++ interface to the optional CUDA solvers (cuSPARSE assembly and CGLS, a matrix-free
// assembly kernel): no CUDA type appears here, so tools/app compiles it with the host compiler.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "field_mapping.h"

namespace tfm::cuda {

// Throws std::runtime_error "<who>: no CUDA device available (cudaGetDeviceCount: <reason>)"
// when the runtime finds no usable device; otherwise selects device 0.
void require_device(const std::string& who);
// True when a CUDA device can be used; `why` gets the runtime's reason otherwise.
bool device_available(std::string* why = nullptr);
std::string device_name();

// A host CSR matrix, 0-based int32 indices (Eigen's RowMajor SparseMatrix layout).
struct CsrView {
  int rows = 0, cols = 0;
  std::span<const int> row_ptr;  // rows + 1
  std::span<const int> col;      // nnz
  std::span<const double> val;   // nnz
};

// A^T A (CSR, cols x cols) by cusparseSpGEMM and A^T b by cusparseSpMV, from the explicit A.
struct CusparseAssembly {
  std::vector<int> row_ptr, col;
  std::vector<double> val;
  std::vector<double> atb;
  double upload_ms = 0.0;    // host to device copies of A and b (wall)
  double assemble_ms = 0.0;  // transpose, SpGEMM and SpMV on the device (CUDA events)
};
CusparseAssembly assemble_cusparse(const CsrView& a, std::span<const double> b);

// The matrix-free assembly (one pass over the voxels, 32.32 fixed-point 64-bit atomics, so the
// sums are exact and do not depend on scheduling), in the TFM_ASSEMBLE_SLOTS layout of
// NormalEquations::from_slots. ref_tf_rgba: the reference TF as 4 floats per entry.
struct DirectAssembly {
  std::vector<double> slots;
  double upload_ms = 0.0;  // fields and TF to the device (wall)
  double kernel_ms = 0.0;  // the assembly kernel (CUDA events)
};
DirectAssembly assemble_direct(std::span<const float> ref, std::span<const float> opt, const FieldMapping& ref_map,
                               const FieldMapping& opt_map, std::span<const float> ref_tf_rgba);

// Jacobi-preconditioned CGLS (Bjorck) on the explicit A = S (x) I_4 (rows 4 per voxel, 4N
// unknowns interleaved by channel) for the four channels independently, with R = ridge I +
// smooth D^T D per channel (absolute weights). A channel stops when ||A^T r - R x||^2 <=
// tolerance^2 ||A^T b||^2, when its step breaks down, or at max_iterations (the Vulkan `cgls`
// rule).
struct CglsParams {
  uint32_t n = 0;                  // TF entries
  double tolerance = 1e-6;
  uint32_t max_iterations = 1000;
  double ridge = 0.0, smooth = 0.0;
  std::span<const double> inv_diag;  // n entries: 1 / diag(M + R) (0 for an unreferenced entry)
};
struct CglsOutcome {
  std::vector<double> x;  // 4n, interleaved (entry j, channel c at 4j + c)
  std::array<uint32_t, 4> iterations{};
  std::array<double, 4> relative_residual{};  // ||s|| / ||s0|| per channel at the end
  double upload_ms = 0.0;   // A, A^T (built on the device) and b (wall)
  double iterate_ms = 0.0;  // the iterations (CUDA events)
};
CglsOutcome cgls(const CsrView& a, std::span<const double> b, const CglsParams& params);

}  // namespace tfm::cuda
