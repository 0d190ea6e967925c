// A built-in synthetic ensemble whose correlation fields differ by measure in known places: the
// `demo --ensemble` input and a test ensemble with known structure.
#pragma once

#include <cstdint>
#include <vector>

#include "tfmatch/model/ensemble.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

// Member m at voxel v is built from two hidden per-member factors z1, z2 ~ N(0, 1):
//   v = a(v) z1 - n(v) z1 + q(v) (z1^2 - 1)/sqrt(2) + c(v) z2 + 0.35 s_m(v)
// where a, n, q and c are Gaussian blobs (a around the reference point, n, q and c elsewhere),
// and s_m is a smooth random wave field per member. Seen from the reference point (where a = 1):
// Pearson is high in a, negative in n, near 0 in q (a non-monotone dependence) and in c
// (independent); mutual information is high in a, n and q alike. Deterministic for a seed,
// on every platform (its own generator and normal deviates).
Ensemble synthetic_ensemble(uint64_t nx, uint64_t ny, uint64_t nz, uint32_t members, uint64_t seed = 1);

// Voxels [begin, end) (linear indices, x fastest) of every member of synthetic_ensemble(nx, ny, nz,
// members, seed), member-major: the same values, without the memory of the whole grid (a
// benchmark of a few voxels over many members).
std::vector<float> synthetic_ensemble_voxels(uint64_t nx, uint64_t ny, uint64_t nz, uint32_t members, uint64_t begin,
                                             uint64_t end, uint64_t seed = 1);

// The reference point of synthetic_ensemble(): the centre of blob a.
GridIndex synthetic_ensemble_reference(const Ensemble& ens);

// A TF for dependence fields (MI, |correlation|): transparent at the low end, opacity and a
// purple-orange-yellow colour rising towards the high end; N entries. `min_opacity` > 0 keeps
// weak dependence visible too (a map of a thin grid, where a transparent voxel leaves a hole
// rather than showing what lies behind it).
TransferFunction correlation_transfer_function(uint32_t n = 64, double min_opacity = 0.0);

// Centres (voxels) and width of the blobs: a, n, q, c.
struct EnsembleBlobs {
  std::array<std::array<double, 3>, 4> centre;
  double sigma;
};
EnsembleBlobs synthetic_ensemble_blobs(uint64_t nx, uint64_t ny, uint64_t nz);

}  // namespace tfm
