// The synthetic ensemble: hidden factors per member, spatial blobs that say how each voxel
// depends on them, and smooth member noise.
#include "tfmatch/model/synthetic_ensemble.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tfm {
namespace {

// splitmix64: a tiny generator with a fixed definition, so the ensemble is the same everywhere
// (std::normal_distribution is implementation-defined).
struct SplitMix {
  uint64_t state;
  uint64_t next() {
    uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  double uniform() { return (double(next() >> 11) + 0.5) / 9007199254740992.0; }  // (0, 1)
  double normal() {  // Box-Muller
    const double u = uniform(), v = uniform();
    return std::sqrt(-2.0 * std::log(u)) * std::cos(2.0 * std::numbers::pi * v);
  }
};

}  // namespace

EnsembleBlobs synthetic_ensemble_blobs(uint64_t nx, uint64_t ny, uint64_t nz) {
  const double x = double(nx), y = double(ny), z = double(nz);
  EnsembleBlobs b;
  b.centre = {{{0.28 * x, 0.5 * y, 0.5 * z},    // a: linear, around the reference point
               {0.62 * x, 0.22 * y, 0.5 * z},   // n: negatively linear
               {0.66 * x, 0.74 * y, 0.5 * z},   // q: non-monotone (z1^2)
               {0.22 * x, 0.18 * y, 0.5 * z}}};  // c: independent factor
  b.sigma = 0.13 * std::max({x, y, z});
  return b;
}

GridIndex synthetic_ensemble_reference(const Ensemble& ens) {
  const auto& d = ens.grid.dims;
  const auto c = synthetic_ensemble_blobs(d[0], d[1], d[2]).centre[0];
  return {uint64_t(std::lround(c[0])), uint64_t(std::lround(c[1])), uint64_t(std::lround(c[2]))};
}

std::vector<float> synthetic_ensemble_voxels(uint64_t nx, uint64_t ny, uint64_t nz, uint32_t members, uint64_t begin,
                                             uint64_t end, uint64_t seed) {
  end = std::min(end, nx * ny * nz);
  begin = std::min(begin, end);
  const uint64_t count = end - begin;
  std::vector<float> values(uint64_t(members) * count);
  const EnsembleBlobs blobs = synthetic_ensemble_blobs(nx, ny, nz);
  // Blob weights per voxel, shared by every member.
  std::vector<std::array<float, 4>> w(count);
  for (uint64_t i = begin; i < end; ++i) {
    const uint64_t x = i % nx, j = i / nx % ny, k = i / (nx * ny);
    for (int b = 0; b < 4; ++b) {
      const auto& c = blobs.centre[b];
      const double d2 = (x - c[0]) * (x - c[0]) + (j - c[1]) * (j - c[1]) + (k - c[2]) * (k - c[2]);
      w[i - begin][b] = float(std::exp(-d2 / (2.0 * blobs.sigma * blobs.sigma)));
    }
  }
  SplitMix rng{seed * 0x2545f4914f6cdd1dull + 1};
  const double two_pi = 2.0 * std::numbers::pi;
  for (uint32_t m = 0; m < members; ++m) {
    const double z1 = rng.normal(), z2 = rng.normal();
    const double q = (z1 * z1 - 1.0) / std::numbers::sqrt2;
    // Three plane waves with random directions and phases, about five periods across the box:
    // smooth to look at, yet correlated over short distances only (the noise of one point says
    // little about a point a fifth of the box away).
    std::array<std::array<double, 4>, 3> waves;
    const double n_max = double(std::max({nx, ny, nz}));
    for (auto& wv : waves) wv = {rng.normal() * 5.0 / n_max, rng.normal() * 5.0 / n_max, rng.normal() * 5.0 / n_max, rng.uniform()};
    float* out = values.data() + uint64_t(m) * count;
    for (uint64_t i = begin; i < end; ++i) {
      const uint64_t x = i % nx, j = i / nx % ny, k = i / (nx * ny);
      double s = 0.0;
      for (const auto& wv : waves) s += std::sin(two_pi * (wv[0] * x + wv[1] * j + wv[2] * k + wv[3]));
      const auto& a = w[i - begin];
      out[i - begin] = float(a[0] * z1 - a[1] * z1 + a[2] * q + a[3] * z2 + 0.35 * s / std::sqrt(1.5));
    }
  }
  return values;
}

Ensemble synthetic_ensemble(uint64_t nx, uint64_t ny, uint64_t nz, uint32_t members, uint64_t seed) {
  Ensemble e;
  e.grid.dims = {nx, ny, nz};
  e.grid.name = "synthetic ensemble";
  e.member_count = members;
  for (uint32_t m = 0; m < members; ++m) e.member_names.push_back("synthetic member " + std::to_string(m));
  e.values = synthetic_ensemble_voxels(nx, ny, nz, members, 0, nx * ny * nz, seed);
  return e;
}

TransferFunction correlation_transfer_function(uint32_t n, double min_opacity) {
  // Opacity a smooth step from 0 (or the floor) below t = 0.3 to 0.9 at the top, so weak
  // dependence is transparent and strong dependence shows as a solid core.
  const ColorStop stops[] = {{0.0, 0.25, 0.05, 0.45}, {0.5, 0.85, 0.25, 0.35}, {0.8, 0.98, 0.62, 0.15},
                             {1.0, 0.99, 0.95, 0.55}};
  return tf_from_color_stops(n, stops, [min_opacity](double t) {
    const double u = std::clamp((t - 0.3) / 0.7, 0.0, 1.0);
    return min_opacity + (0.9 - min_opacity) * u * u * (3 - 2 * u);
  });
}

}  // namespace tfm
