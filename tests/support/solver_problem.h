// Test support for the solver tests: a voxel problem (host volumes, device fields, reference TF)
// built from generated fields, its double-precision CPU normal equations, and a runner for any
// registered solver.
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm::test {

struct SolverProblem {
  Volume ref_volume, opt_volume;
  TransferFunction ref_tf;
  FieldMapping ref_map, opt_map;
  std::unique_ptr<DeviceField> ref, opt;
  std::unique_ptr<Buffer> ref_tf_buffer;

  // Puts the fields on the device (chunks of `max_chunk_voxels`, 0: device limit).
  void upload(Context& ctx, uint64_t max_chunk_voxels = 0) {
    ref = std::make_unique<DeviceField>(ctx, ref_volume.values, "test ref", max_chunk_voxels);
    opt = std::make_unique<DeviceField>(ctx, opt_volume.values, "test opt", max_chunk_voxels);
    ref_tf_buffer = std::make_unique<Buffer>(upload_tf(ctx, ref_tf, "test ref tf"));
  }
  NormalEquations cpu_equations() const {
    return assemble_normal_equations_cpu(ref_volume.values, opt_volume.values, ref_map, opt_map, ref_tf);
  }
  // The problem on the device (upload() first), for the typed solver calls.
  VoxelProblem problem(Context& ctx) const {
    return VoxelProblem{ctx, ref_volume, opt_volume, *ref, *opt, ref_map, opt_map, ref_tf, *ref_tf_buffer,
                        ref_tf.resampled(opt_map.tf_size)};
  }
  // Voxel i's optimized-TF coordinate (entry j, weight w) and b as the kernels compute them (float
  // TF entries, double arithmetic, clamped); false when either field has no data there.
  bool voxel_terms(size_t i, uint32_t& j, float& w, double b[4]) const {
    uint32_t jr;
    float wr;
    if (!tf_coordinate(ref_volume.values[i], ref_map, jr, wr) || !tf_coordinate(opt_volume.values[i], opt_map, j, w))
      return false;
    for (int c = 0; c < 4; ++c)
      b[c] = std::clamp((1.0 - wr) * float(ref_tf.rgba[jr][c]) + double(wr) * float(ref_tf.rgba[jr + 1][c]), 0.0, 1.0);
    return true;
  }
  // Runs the registered solver `solver` with `settings` (options parsed as the command line's).
  SolverOutput solve(Context& ctx, const std::string& solver, const SolverSettings& settings = {}) {
    VoxelProblem p = problem(ctx);
    return run_solver(solver, p, settings);
  }
};

// Reference field uniform on [0,1]; second field a monotone, nonlinear remap of it in [10, 20]
// (plus `noise`, fraction `nan_every` NaN), so the least-squares TF is well determined.
// `ref_tf_entries` random RGBA entries in [tf_lo, tf_hi].
inline SolverProblem make_solver_problem(size_t voxels, uint32_t n, uint32_t ref_tf_entries, double tf_lo,
                                         double tf_hi, uint32_t seed, double noise = 0.0, size_t nan_every = 0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  SolverProblem p;
  p.ref_volume.dims = {voxels, 1, 1};
  p.opt_volume.dims = {voxels, 1, 1};
  p.ref_volume.values.resize(voxels);
  p.opt_volume.values.resize(voxels);
  for (size_t i = 0; i < voxels; ++i) {
    const double t = u(rng);
    p.ref_volume.values[i] = float(t);
    p.opt_volume.values[i] = float(10.0 + 10.0 * std::pow(std::clamp(t + noise * (u(rng) - 0.5), 0.0, 1.0), 1.3));
    if (nan_every && i % nan_every == nan_every / 2) p.opt_volume.values[i] = NAN;
  }
  p.ref_tf.rgba.resize(ref_tf_entries);
  for (auto& e : p.ref_tf.rgba)
    for (double& c : e) c = tf_lo + (tf_hi - tf_lo) * u(rng);
  p.ref_map = make_mapping({0.0, 1.0}, ref_tf_entries);
  p.opt_map = make_mapping({10.0, 20.0}, n);
  return p;
}

// Largest |a - b| over all entries and channels; infinite for TFs of different sizes or none,
// so that a solver returning no TF fails every bound on it.
inline double max_difference(const TransferFunction& a, const TransferFunction& b) {
  if (a.size() != b.size() || a.size() == 0) return INFINITY;
  double worst = 0.0;
  for (size_t j = 0; j < a.size(); ++j)
    for (int c = 0; c < 4; ++c) worst = std::max(worst, std::abs(a.rgba[j][c] - b.rgba[j][c]));
  return worst;
}

// Every component of a non-empty TF finite and within [0, 1].
inline bool all_finite_in_box(const TransferFunction& tf) {
  if (tf.rgba.empty()) return false;
  for (const auto& e : tf.rgba)
    for (double c : e)
      if (!std::isfinite(c) || c < 0.0 || c > 1.0) return false;
  return true;
}

}  // namespace tfm::test
