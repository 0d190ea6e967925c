// The optimization pipeline behind `tfmatch optimize` and `tfmatch demo`: resolve ranges, put
// both fields on the device, run the chosen solver, measure voxel loss before and after.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "context.h"
#include "device_field.h"
#include "gpu_voxel_ops.h"
#include "normal_equations.h"
#include "render_settings.h"
#include "transfer_function.h"
#include "volume.h"

namespace tfm {

struct PhaseTime {
  std::string name;
  double wall_ms = 0.0;
  double gpu_ms = -1.0;  // -1: not measured on the GPU
};

// Everything a voxel solver sees: both fields on the device, their mappings, the reference TF.
struct VoxelProblem {
  Context& ctx;
  const Volume& ref_volume;      // host copies (dims, spacing; image-based solvers render them)
  const Volume& opt_volume;
  const DeviceField& ref;
  const DeviceField& opt;
  FieldMapping ref_map;
  FieldMapping opt_map;          // tf_size = N of the TF being optimized
  const TransferFunction& ref_tf;
  const Buffer& ref_tf_buffer;
  TransferFunction initial;      // the reference TF resampled to N (starting point)
};

struct SolverSettings {
  SolveOptions solve;                 // regularization, factorization
  // Solver-specific settings from the command line, by flag name without dashes ("loss",
  // "optimizer", "lr", "iterations", "tolerance", "max-iterations", "seed", "views-per-iteration",
  // "image-size", "init", ...). A solver reads what it understands and rejects bad values.
  std::map<std::string, std::string> extra;
  // The optical model and camera of the renderings (image-based solvers render with these, so
  // the images optimized are the images shown; the image size comes from "image-size").
  RenderSettings render;
  // extra[name] as a number, or `fallback`; throws std::runtime_error naming the flag when the
  // value is not a number.
  double number(const std::string& name, double fallback) const;
  std::string text(const std::string& name, const std::string& fallback) const;
};

struct SolverOutput {
  TransferFunction tf;                // in [0,1]
  std::vector<PhaseTime> phases;
  std::vector<std::string> warnings;
  nlohmann::json details;             // solver-specific numbers (cond, iterations, ...)
};

using SolverFn = std::function<SolverOutput(VoxelProblem&, const SolverSettings&)>;
// Solvers by name (the explicit list of host/solvers/solver_registry.h).
std::map<std::string, SolverFn>& solver_registry();
std::vector<std::string> solver_names();

struct OptimizeRequest {
  const Volume* ref = nullptr;
  const Volume* field = nullptr;
  TransferFunction ref_tf;
  std::optional<FieldRange> ref_range;    // user ranges; default: TF file's range, then finite min/max
  std::optional<FieldRange> field_range;
  uint32_t tf_size = 64;
  std::string solver = "normal-equations";
  SolverSettings settings;
  uint64_t max_chunk_voxels = 0;          // 0: device limit
};

struct OptimizeResult {
  TransferFunction tf;                    // optimized, with range = field range
  std::string solver;
  FieldRange ref_range, field_range;
  VoxelLoss before;                       // field with the reference TF
  VoxelLoss after;                        // field with the optimized TF
  uint64_t voxels_total = 0;
  std::vector<PhaseTime> phases;
  std::vector<std::string> warnings;
  nlohmann::json details;
  std::string device;

  nlohmann::json to_json() const;
  void print_summary(std::ostream& os) const;
};

// Throws std::runtime_error for unusable input (grids differ, constant field, unknown solver).
OptimizeResult run_optimize(Context& ctx, const OptimizeRequest& request);

}  // namespace tfm
