// The interface of the optional CUDA solvers (cuSPARSE assembly and CGLS, a matrix-free assembly
// kernel). Their code is a plugin, libtfmatch_cuda.so, which alone links the CUDA runtime and
// cuSPARSE: a program loads it on first use (cuda_backend.h in host/solvers/cuda), so no other
// command pays for loading CUDA's libraries and a machine without them runs everything else. No
// CUDA type appears here, so the host compiler reads it; the plugin and its loader are built
// from the same copy of it (its hash is the plugin's interface tag, checked at load).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/model/field_mapping.h"

namespace tfm::cuda {

// The two fields on the device, uploaded once for the system and the assemblies below; made by
// Backend::upload.
class DeviceFields {
 public:
  virtual ~DeviceFields() = default;
  size_t voxels() const { return voxels_; }
  double upload_ms() const { return upload_ms_; }  // both fields to the device (wall)

 protected:
  size_t voxels_ = 0;
  double upload_ms_ = 0.0;
};

// The paper's explicit system, built on the device by Backend::build_system: A = S (x) I_4 (4
// rows per voxel with data in both fields; S has one, with 1 - w and w at the field's TF
// coordinate j and j + 1) and b (the reference colours, RGBA per voxel), by a counting pass, a
// scan and a fill, then S^T by cuSPARSE. The solvers work on S: A's products are S's applied to
// RGBA columns. A (S expanded), b and their order are bit for bit build_explicit_system()'s
// (host/solvers/eigen_baseline.h). S's 32-bit CSR indices hold 1 073 741 823 voxels.
class DeviceSystem {
 public:
  virtual ~DeviceSystem() = default;
  uint64_t voxels() const { return voxels_; }  // voxels with data in both fields
  int64_t nonzeros() const { return 8 * int64_t(voxels_); }  // of A, as the paper counts them
  std::array<double, 4> btb() const { return btb_; }  // b^T b per channel, a fixed-shape device sum
  double build_ms() const { return build_ms_; }      // count, scan, fill and S^T (CUDA events)
  // diag(S^T S): the squared column norms of S, each summed on the device in a fixed shape (the
  // same bits every run).
  virtual std::vector<double> column_norms() const = 0;
  // S and b copied back, for tests: CSR with 0-based indices; b RGBA per voxel.
  struct Host {
    std::vector<int> row_ptr, col;
    std::vector<double> val, b;
  };
  virtual Host download() const = 0;

 protected:
  uint64_t voxels_ = 0;
  std::array<double, 4> btb_{};
  double build_ms_ = 0.0;
};

// Backend::assemble_cusparse, the normal equations by cuSPARSE: S^T S (CSR, n x n, tridiagonal)
// by cusparseSpGEMM and S^T B (n x 4 row-major: A^T b interleaved by channel) by cusparseSpMM.
struct CusparseAssembly {
  std::vector<int> row_ptr, col;
  std::vector<double> val;
  std::vector<double> stb;
  double assemble_ms = 0.0;  // SpGEMM and SpMM on the device (CUDA events)
};

// Backend::assemble_direct, the matrix-free assembly (one pass over the voxels, 32.32 fixed-point
// 64-bit atomics, so the sums are exact and do not depend on scheduling), in the
// TFM_ASSEMBLE_SLOTS layout of NormalEquations::from_slots. ref_tf_rgba: the reference TF as 4
// floats per entry.
struct DirectAssembly {
  std::vector<double> slots;
  double kernel_ms = 0.0;  // the assembly kernel (CUDA events)
};

// Backend::cgls, Jacobi-preconditioned CGLS (Bjorck) on the explicit A = S (x) I_4 (rows 4 per
// voxel, 4N unknowns interleaved by channel; A's products are S's on N x 4 and voxels x 4
// matrices) for the four channels independently, with R = ridge I + smooth D^T D per channel (absolute
// weights). A channel stops when ||A^T r - R x||^2 <= tolerance^2 ||A^T b||^2, when its step
// breaks down, or at max_iterations (the Vulkan `cgls` rule).
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
  double setup_ms = 0.0;    // the iteration's vectors and descriptors (wall)
  double iterate_ms = 0.0;  // the iterations (CUDA events)
};

// What the plugin offers. Every call throws std::runtime_error on a CUDA or cuSPARSE failure and
// std::invalid_argument for arguments that do not fit (fields of different sizes, a TF that does
// not match its mapping, a system without voxels, objects another backend made).
class Backend {
 public:
  virtual ~Backend() = default;
  // True when a CUDA device can be used; `why` gets the runtime's reason otherwise.
  virtual bool device_available(std::string* why = nullptr) const = 0;
  // Throws std::runtime_error "<who>: no CUDA device available (cudaGetDeviceCount: <reason>)"
  // when the runtime finds no usable device; otherwise selects device 0.
  virtual void require_device(const std::string& who) const = 0;
  virtual std::string device_name() const = 0;
  virtual std::unique_ptr<DeviceFields> upload(std::span<const float> ref, std::span<const float> opt) const = 0;
  virtual std::unique_ptr<DeviceSystem> build_system(const DeviceFields& fields, const FieldMapping& ref_map,
                                                     const FieldMapping& opt_map,
                                                     std::span<const float> ref_tf_rgba) const = 0;
  virtual CusparseAssembly assemble_cusparse(const DeviceSystem& system) const = 0;
  virtual DirectAssembly assemble_direct(const DeviceFields& fields, const FieldMapping& ref_map,
                                         const FieldMapping& opt_map, std::span<const float> ref_tf_rgba) const = 0;
  virtual CglsOutcome cgls(const DeviceSystem& system, const CglsParams& params) const = 0;
};

// The plugin's one entry point, looked up by this name: its Backend when `interface_tag` is the
// tag it was built with (the loader's copy of this header is the plugin's), else null.
using BackendEntry = const Backend* (*)(const char* interface_tag);
inline constexpr const char* kBackendEntryName = "tfmatch_cuda_backend";

}  // namespace tfm::cuda
