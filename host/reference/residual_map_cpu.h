// CPU reference of the residual-map kernel (shaders/residual_map.comp, DESIGN.md's residual): per
// voxel || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2 in double, each TF evaluated at the shader's
// float32 coordinate (tf_coordinate: the same entry and weight bits), interpolated in double and
// clamped to [0, 1]; 0 where either field has no data (NaN).
#pragma once

#include <span>
#include <vector>

#include "tfmatch/model/field_mapping.h"

namespace tfm {

// T(v): the RGBA colour of table `tf` (4 floats an entry) at value `v` through `map`, at the
// shaders' float32 coordinate (tf_coordinate), interpolated in double and clamped to [0, 1];
// false where `v` has no data (NaN). The CPU references' TF lookup.
bool tf_colour_cpu(std::span<const float> tf, const FieldMapping& map, float v, double out[4]);

// `ref_tf` and `opt_tf` are RGBA tables (4 floats an entry) of the sizes their mappings read.
std::vector<double> residual_map_cpu(std::span<const float> ref, std::span<const float> opt,
                                     std::span<const float> ref_tf, const FieldMapping& ref_map,
                                     std::span<const float> opt_tf, const FieldMapping& opt_map);

}  // namespace tfm
