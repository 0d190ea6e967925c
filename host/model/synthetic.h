// Built-in synthetic fields: the demo pair and test volumes with known structure.
#pragma once

#include <cstdint>
#include <vector>

#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// A smooth reference field on [0,1] (a few Gaussian blobs over a gentle gradient), deterministic.
Volume synthetic_reference(uint64_t nx, uint64_t ny, uint64_t nz);

// The demo's second field: a nonlinear, partly non-monotone remap g of the reference, in other
// units (g(t) = 40 + 300 * (0.55 + 0.45 sin(2.6 pi t - 0.9))), plus a sphere of real structural
// difference (a different pattern) that no transfer function can explain.
Volume synthetic_remapped(const Volume& reference, bool with_structural_difference = true);

// The default demo's second field: a monotone nonlinear remap of the reference into other units
// (g(t) = 250 + 60 (exp(1.6 t) - 1) / (exp(1.6) - 1), "kelvin"), with a little deterministic noise
// (0.2 % of the range), plus two regions of real structural change that no TF can explain: the
// sphere of synthetic_difference_region() filled with another pattern, and one blob of the
// reference moved by a tenth of the box. Where the fields differ in structure, `changed` (when
// given) gets 1 per voxel, else 0: the sphere, and every voxel where the moved blob changes the
// reference's value by more than 0.02 of its range.
Volume synthetic_changed(const Volume& reference, std::vector<uint8_t>* changed = nullptr);
// The solver that fits synthetic_changed()'s pair by default (tfmatch demo, tfmatch view --demo):
// least absolute deviations keep its two real changes out of the TF, where least squares makes
// each entry the mean of the colours its voxels ask for and spreads the changes over the field.
inline constexpr const char* kChangedPairSolver = "irls";

// Centre and radius (in voxels) of the structural-difference sphere of synthetic_remapped().
struct Sphere {
  double cx, cy, cz, r;
};
Sphere synthetic_difference_region(const Volume& reference);

// The demo's reference TF: N entries, a blue-cyan-yellow-red colour map with opacity peaks.
TransferFunction demo_transfer_function(uint32_t n = 64);

}  // namespace tfm
