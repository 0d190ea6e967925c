// Built-in synthetic fields: the demo pair and test volumes with known structure.
#pragma once

#include <cstdint>

#include "transfer_function.h"
#include "volume.h"

namespace tfm {

// A smooth reference field on [0,1] (a few Gaussian blobs over a gentle gradient), deterministic.
Volume synthetic_reference(uint64_t nx, uint64_t ny, uint64_t nz);

// The demo's second field: a nonlinear, partly non-monotone remap g of the reference, in other
// units (g(t) = 40 + 300 * (0.55 + 0.45 sin(2.6 pi t - 0.9))), plus a sphere of real structural
// difference (a different pattern) that no transfer function can explain.
Volume synthetic_remapped(const Volume& reference, bool with_structural_difference = true);

// Centre and radius (in voxels) of the structural-difference sphere of synthetic_remapped().
struct Sphere {
  double cx, cy, cz, r;
};
Sphere synthetic_difference_region(const Volume& reference);

// The demo's reference TF: N entries, a blue-cyan-yellow-red colour map with opacity peaks.
TransferFunction demo_transfer_function(uint32_t n = 64);

}  // namespace tfm
