// Double-precision CPU reference of the GPU normal-equation assembly (assemble_normal_equations.comp).
#pragma once

#include <span>

#include "field_mapping.h"
#include "normal_equations_system.h"
#include "transfer_function.h"

namespace tfm {

// Double-precision CPU reference of the GPU assembly: the same float32 TF coordinates
// (tf_coordinate), every product and sum in double.
NormalEquations assemble_normal_equations_cpu(std::span<const float> ref, std::span<const float> opt,
                                              const FieldMapping& ref_map, const FieldMapping& opt_map,
                                              const TransferFunction& ref_tf);
// Adds more voxels to `eq` (for streaming references over large synthetic volumes).
void accumulate_normal_equations_cpu(NormalEquations& eq, std::span<const float> ref, std::span<const float> opt,
                                     const FieldMapping& ref_map, const FieldMapping& opt_map,
                                     const TransferFunction& ref_tf);

}  // namespace tfm
