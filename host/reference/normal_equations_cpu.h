// Double-precision CPU reference of the GPU normal-equation assembly (assemble_normal_equations.comp).
#pragma once

#include <array>

#include <cstdint>
#include <span>
#include <vector>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/normal_equations_system.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

// Double-precision CPU reference of the GPU assembly: the same float32 TF coordinates
// (tf_coordinate), every product and sum in double.
NormalEquations assemble_normal_equations_cpu(std::span<const float> ref, std::span<const float> opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              const TransferFunction& ref_tf);
// The exact totals of the GPU assembly: per voxel the same float32 terms (including b clamped
// to [0, 1]), each converted to floor(term 2^32) and summed modulo 2^64, in the slot layout of
// TFM_ASSEMBLE_SLOTS(N). Every mode, atomic width and chunking of the kernel must give these
// bits exactly; with `before_map`, the before-loss slots too; with `weights` (one per voxel, in
// [0, 1]) the weighted assembly's, each term times its voxel's weight rounded once to float.
// Throws std::invalid_argument when the sizes or TF sizes do not match.
std::vector<uint64_t> assemble_normal_equations_fixed_point(std::span<const float> ref, std::span<const float> opt,
                                                            const FieldMapping& ref_map, const FieldMapping& opt_map,
                                                            const TransferFunction& ref_tf,
                                                            const FieldMapping* before_map = nullptr,
                                                            std::span<const float> weights = {});
// The loss before optimization the assembly sums alongside (its before slots), in double: per
// channel the sum over voxels with data in both fields of (T_r(F_o through `before_map`) - b)^2,
// b = T_r(F_r) clamped to [0, 1], both at the float32 TF coordinates.
std::array<double, 4> before_loss_cpu(std::span<const float> ref, std::span<const float> opt,
                                      const FieldMapping& ref_map, const FieldMapping& before_map,
                                      const TransferFunction& ref_tf);
// The same double-precision sums with `threads` threads (0: all cores), each over a contiguous
// part of the voxels into its own system, added at the end: the plain multi-threaded CPU loop
// `tfmatch bench` measures the GPU assembly against. Agrees with the one-thread reference to
// double rounding.
NormalEquations assemble_normal_equations_cpu_threaded(std::span<const float> ref, std::span<const float> opt,
                                                       const FieldMapping& ref_map, const FieldMapping& opt_map,
                                                       const TransferFunction& ref_tf, unsigned threads = 0);
// Adds more voxels to `eq` (for streaming references over large synthetic volumes).
void accumulate_normal_equations_cpu(NormalEquations& eq, std::span<const float> ref, std::span<const float> opt,
                                     const FieldMapping& ref_map, const FieldMapping& opt_map,
                                     const TransferFunction& ref_tf);

}  // namespace tfm
