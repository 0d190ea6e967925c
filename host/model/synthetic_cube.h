// The paper's synthetic cube pair (its Fig. "cube" and Table 3): a reference field that is 0 on
// the left half of a cube and 1 on the right, and a second field with a smaller centred cube of
// opposite values inside, rendered with a blue-to-red TF. The interior is hardly visible, so
// image-based optimization keeps the TF while voxel-based least squares averages the colours.
#pragma once

#include <cstdint>

#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// n^3 voxels: 0 where x < n/2, else 1.
Volume cube_halves(uint64_t n);
// cube_halves(n) with the values flipped (v -> 1 - v) inside the centred cube of side
// inner_fraction * n (voxel centres strictly inside). Throws std::invalid_argument unless
// 0 < inner_fraction < 1.
Volume cube_with_inner_cube(uint64_t n, double inner_fraction = 0.5);
// n entries from blue (t = 0) to red (t = 1) with constant opacity.
TransferFunction blue_to_red_tf(uint32_t n, double opacity);

}  // namespace tfm
