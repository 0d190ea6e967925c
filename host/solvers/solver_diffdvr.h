// Image-based TF optimization (DiffDVR, solver "diffdvr"): the GPU evaluation of the image loss
// and its gradient w.r.t. the TF for a batch of cameras, and the optimizer loop as a typed call
// (solver_diffdvr_optimize.cpp).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/diffdvr.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/reference/diffdvr_cpu.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

struct ImageLossGradient {
  double loss = 0.0;               // sum over views, pixels and RGBA components
  std::vector<double> gradient;    // dLoss/dT[j][c] of that sum at 4j + c
  uint64_t components = 0;         // 4 * pixels * views: divide by it for the mean
  double forward_gpu_ms = -1.0;    // both forward passes; -1 without timestamps
  double backward_gpu_ms = -1.0;
};

// The GPU passes of one field pair. For each batch of cameras: the forward kernel renders the
// reference field with its TF (the target) and the second field with the candidate TF, keeping
// each pixel's final state; the backward kernel re-marches the second field's rays and adds the
// loss and its TF gradient. Views are processed in groups small enough that one image buffer
// fits a storage descriptor and the fixed-point sums cannot overflow; one submission in all.
// Deterministic: the same inputs give the same bits.
class DiffDvrGradient {
 public:
  // `settings`: the optical model and the image size (width x height) of every view; the camera
  // pose comes with each evaluation. Both fields live on `geometry`. `reduction` forces the
  // backward kernel's summing mode (DiffDvrBackwardKernel; tests run each), `max_group_views`
  // smaller view groups (the same bits as one group). Throws std::runtime_error for invalid
  // settings or a field too large for the kernels.
  DiffDvrGradient(Context& ctx, const DeviceField& ref, const DeviceField& opt, const VolumeGeometry& geometry,
                  const FieldMapping& ref_map, const Buffer& ref_tf, const FieldMapping& opt_map,
                  const RenderSettings& settings, ImageLoss loss, ReductionMode reduction = ReductionMode::Auto,
                  uint32_t max_group_views = 64);
  ~DiffDvrGradient();

  // Loss and gradient of the second field's images with `tf` (opt_map.tf_size entries) against
  // the reference images, over `cameras` (distance and fov as given; width/height from the
  // settings). Reference images are rendered again unless the cameras equal the last call's
  // and fit one group.
  ImageLossGradient evaluate(const TransferFunction& tf, std::span<const OrbitCamera> cameras);
  // Renders the reference images of `cameras` once and keeps them: evaluate_pooled() then renders
  // only the second field. Replaces an earlier pool; 16 bytes per pixel and camera.
  void set_view_pool(std::span<const OrbitCamera> cameras);
  uint32_t pool_size() const { return uint32_t(pool_cameras_.size()); }
  // evaluate() for the pool's cameras indices[0], indices[1], ... against their kept reference
  // images. Throws std::invalid_argument for an index past the pool or an empty list.
  ImageLossGradient evaluate_pooled(const TransferFunction& tf, std::span<const uint32_t> indices);
  // Views per group (per dispatch) for this image size.
  uint32_t views_per_group() const { return group_; }
  // Backward passes (view groups x row bands) the last evaluation summed.
  uint32_t last_pass_count() const { return passes_; }

 private:
  struct Buffers;
  Context& ctx_;
  const DeviceField& ref_;
  const DeviceField& opt_;
  VolumeGeometry geometry_;
  FieldMapping ref_map_, opt_map_;
  const Buffer& ref_tf_;
  RenderSettings settings_;
  MarchConstants march_;
  DiffDvrForwardKernel forward_ref_, forward_opt_;
  DiffDvrBackwardKernel backward_;
  uint32_t group_ = 1;
  uint32_t passes_ = 0;
  std::unique_ptr<Buffers> buffers_;
  std::vector<OrbitCamera> cached_cameras_;  // whose reference images the target buffer holds
  std::vector<OrbitCamera> pool_cameras_;
  std::vector<Buffer> pool_images_;          // reference image (C, T) of each pool camera

  // evaluate() and evaluate_pooled(): `pooled` gives the pool index of each camera, or is empty
  // when the reference images are rendered here.
  ImageLossGradient evaluate_views(const TransferFunction& tf, std::span<const OrbitCamera> cameras,
                                   std::span<const uint32_t> pooled);
};

enum class DiffDvrStart { Reference, NormalEquations };

// The largest smoothness weight of diffdvr (absolute: beside the mean image loss, not scaled as
// the voxel solvers' relative --smooth). The image loss's gradient per TF entry is at most O(1),
// so at 1e9 the minimizer's neighbouring entries are within ~1e-11 of each other: the constant TF any
// heavier weight tends to. Beyond, the penalty's doubles only head for overflow (at 1e300 Adam
// was fed infinite gradients and left entries such as an opacity of 5e-19).
constexpr double kMaxDiffDvrSmooth = 1e9;

// Settings of the optimizer loop (solver "diffdvr": its options and SolverArgs::render).
struct DiffDvrOptions {
  ImageLoss loss = ImageLoss::L2;
  uint32_t iterations = 200;               // >= 1
  uint32_t views_per_iteration = 8;        // >= 1
  // Random cameras come from a pool of this many, drawn once from `seed`, whose reference images
  // are rendered once; each iteration takes views_per_iteration of them (seeded). 0: new random
  // cameras and reference renderings every iteration. At least views_per_iteration when not 0.
  uint32_t view_pool = 32;
  uint64_t seed = 1;                       // of the random cameras
  bool fibonacci = false;                  // fixed Fibonacci-sphere cameras instead of random ones
  DiffDvrStart start = DiffDvrStart::Reference;  // the reference TF resampled, or the normal-equations TF
  SolveOptions normal_equations;           // for start = NormalEquations
  double learning_rate = 0.02;             // Adam, in (0, 1]
  double smooth = 0.0;                     // weight of the TF's squared first differences, in [0, kMaxDiffDvrSmooth]
  RenderSettings render;                   // optical model, camera distance / fov, image width and height
};

struct DiffDvrResult {
  TransferFunction tf;                     // in [0,1]
  std::vector<double> loss_curve;          // mean loss plus penalty before each step, on that step's views
  double fixed_view_loss_initial = 0.0;    // mean image loss of the initial and final TF on the
  double fixed_view_loss_final = 0.0;      // Fibonacci views (comparable between runs and seeds)
  uint32_t fixed_views = 0;
  uint32_t views_per_group = 0;            // views per dispatch
  double forward_gpu_ms = -1.0, backward_gpu_ms = -1.0;  // summed over iterations; -1 without timestamps
  std::vector<PhaseTime> phases;
  std::vector<std::string> warnings;
};

// Projected Adam on the mean image loss (plus the smoothness prior) over batches of cameras.
// Deterministic for a seed. Throws std::invalid_argument for options out of range,
// std::runtime_error for invalid render settings or a field too large for the kernels,
// VulkanError for device failures.
DiffDvrResult solve_diffdvr_gpu(VoxelProblem& problem, const DiffDvrOptions& options);

}  // namespace tfm
