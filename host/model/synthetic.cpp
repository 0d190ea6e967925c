// Deterministic synthetic volumes for the demo and tests.
#include "tfmatch/model/synthetic.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <numbers>
#include <span>

namespace tfm {

namespace {

struct Blob {
  double x, y, z, s, a;  // centre and width (box units), amplitude
};
constexpr Blob kBlobs[] = {{0.30, 0.35, 0.40, 0.16, 0.85}, {0.68, 0.62, 0.55, 0.20, 0.70},
                           {0.45, 0.75, 0.30, 0.10, 0.55}, {0.70, 0.25, 0.70, 0.12, 0.60}};
// The blob synthetic_changed() moves (the small one at the back), and by how much (box units).
constexpr size_t kMovedBlob = 2;
constexpr double kBlobShift[3] = {0.10, -0.05, 0.06};

// Gaussian blobs over a gentle gradient, clamped to 1.
Volume blob_field(uint64_t nx, uint64_t ny, uint64_t nz, std::span<const Blob> blobs) {
  Volume v;
  v.dims = {nx, ny, nz};
  v.values.resize(nx * ny * nz);
  for (uint64_t z = 0; z < nz; ++z)
    for (uint64_t y = 0; y < ny; ++y)
      for (uint64_t x = 0; x < nx; ++x) {
        double px = (x + 0.5) / nx, py = (y + 0.5) / ny, pz = (z + 0.5) / nz;
        double f = 0.15 * pz;
        for (const Blob& b : blobs) {
          double d2 = (px - b.x) * (px - b.x) + (py - b.y) * (py - b.y) + (pz - b.z) * (pz - b.z);
          f += b.a * std::exp(-d2 / (2 * b.s * b.s));
        }
        v.values[(z * ny + y) * nx + x] = static_cast<float>(std::min(f, 1.0));
      }
  return v;
}

// Deterministic noise in [-1, 1] per voxel index (a 64-bit mix: the same on every platform).
double voxel_noise(uint64_t i) {
  uint64_t h = i * 0x9e3779b97f4a7c15ull;
  h ^= h >> 31;
  h *= 0xbf58476d1ce4e5b9ull;
  h ^= h >> 29;
  return double(h >> 11) * 0x1p-52 - 1.0;
}

}  // namespace

Volume synthetic_reference(uint64_t nx, uint64_t ny, uint64_t nz) {
  Volume v = blob_field(nx, ny, nz, kBlobs);
  v.name = "synthetic reference";
  return v;
}

Volume synthetic_changed(const Volume& ref, std::vector<uint8_t>* changed) {
  const auto [nx, ny, nz] = ref.dims;
  Blob moved[std::size(kBlobs)];
  std::copy(std::begin(kBlobs), std::end(kBlobs), moved);
  moved[kMovedBlob].x += kBlobShift[0];
  moved[kMovedBlob].y += kBlobShift[1];
  moved[kMovedBlob].z += kBlobShift[2];
  Volume v = blob_field(nx, ny, nz, moved);
  v.name = "synthetic changed";
  v.spacing = ref.spacing;
  v.origin = ref.origin;
  if (changed) changed->assign(v.values.size(), 0);
  const Sphere s = synthetic_difference_region(ref);
  for (uint64_t z = 0; z < nz; ++z)
    for (uint64_t y = 0; y < ny; ++y)
      for (uint64_t x = 0; x < nx; ++x) {
        const size_t i = (z * ny + y) * nx + x;
        double t = v.values[i];
        bool differs = std::abs(t - double(ref.values[i])) > 0.02;
        const double dx = x - s.cx, dy = y - s.cy, dz = z - s.cz;
        if (dx * dx + dy * dy + dz * dz < s.r * s.r) {
          t = 0.5 + 0.5 * std::sin(0.9 * double(x) + 0.4 * double(z));  // another pattern
          differs = true;
        }
        if (changed) (*changed)[i] = differs ? 1 : 0;
        const double kelvin = 250.0 + 60.0 * std::expm1(1.6 * t) / std::expm1(1.6);
        v.values[i] = static_cast<float>(kelvin + 0.002 * 60.0 * voxel_noise(i));
      }
  return v;
}

Sphere synthetic_difference_region(const Volume& r) {
  return {0.70 * r.dims[0], 0.62 * r.dims[1], 0.55 * r.dims[2], 0.14 * double(std::min({r.dims[0], r.dims[1], r.dims[2]}))};
}

Volume synthetic_remapped(const Volume& ref, bool with_structural_difference) {
  Volume v = ref;
  v.name = "synthetic remapped";
  const double pi = std::numbers::pi;
  Sphere s = synthetic_difference_region(ref);
  const auto [nx, ny, nz] = ref.dims;
  for (uint64_t z = 0; z < nz; ++z)
    for (uint64_t y = 0; y < ny; ++y)
      for (uint64_t x = 0; x < nx; ++x) {
        size_t i = (z * ny + y) * nx + x;
        double t = ref.values[i];
        if (with_structural_difference) {
          double dx = x - s.cx, dy = y - s.cy, dz = z - s.cz;
          if (dx * dx + dy * dy + dz * dz < s.r * s.r) {
            // Inside: a striped pattern unrelated to the reference.
            t = 0.5 + 0.5 * std::sin(0.9 * double(x) + 0.4 * double(z));
          }
        }
        v.values[i] = static_cast<float>(40.0 + 300.0 * (0.55 + 0.45 * std::sin(2.6 * pi * t - 0.9)));
      }
  return v;
}

TransferFunction demo_transfer_function(uint32_t n) {
  // Blue-cyan-yellow-red; low values transparent, opacity peaks at mid and high values.
  const ColorStop stops[] = {{0.0, 0.10, 0.15, 0.60}, {0.35, 0.10, 0.70, 0.85}, {0.6, 0.95, 0.90, 0.25},
                             {1.0, 0.85, 0.10, 0.10}};
  TransferFunction tf = tf_from_color_stops(n, stops, [](double t) {
    return 0.05 * t + 0.45 * std::exp(-std::pow((t - 0.45) / 0.07, 2)) + 0.8 * std::exp(-std::pow((t - 0.8) / 0.1, 2));
  });
  tf.range = FieldRange{0.0, 1.0};
  return tf;
}

}  // namespace tfm
