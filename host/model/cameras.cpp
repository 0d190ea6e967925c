// Random and Fibonacci-sphere camera poses.
#include "tfmatch/model/cameras.h"

#include <cmath>
#include <numbers>

namespace tfm {
namespace {

constexpr double kDegrees = 180.0 / std::numbers::pi;

// The pose looking at the box centre from direction (azimuth, z) with z = sin(elevation).
OrbitCamera pose(const OrbitCamera& base, double azimuth_deg, double z) {
  OrbitCamera c = base;
  c.azimuth_deg = azimuth_deg;
  c.elevation_deg = std::asin(std::fmax(-1.0, std::fmin(1.0, z))) * kDegrees;
  return c;
}

}  // namespace

RandomCameras::RandomCameras(uint64_t seed, const OrbitCamera& base) : rng_(seed), base_(base) {}

double RandomCameras::uniform() { return double(rng_() >> 11) * 0x1.0p-53; }

std::vector<OrbitCamera> RandomCameras::next(uint32_t count) {
  std::vector<OrbitCamera> out;
  out.reserve(count);
  for (uint32_t i = 0; i < count; ++i) {
    // Archimedes: z = sin(elevation) uniform in [-1, 1] and an independent uniform azimuth give
    // directions uniform on the sphere.
    const double z = 2.0 * uniform() - 1.0;
    const double azimuth = 360.0 * uniform();
    out.push_back(pose(base_, azimuth, z));
  }
  return out;
}

std::vector<OrbitCamera> fibonacci_cameras(uint32_t count, const OrbitCamera& base) {
  const double golden_angle_deg = 180.0 * (3.0 - std::sqrt(5.0));
  std::vector<OrbitCamera> out;
  out.reserve(count);
  for (uint32_t i = 0; i < count; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / count;
    out.push_back(pose(base, std::fmod(golden_angle_deg * i, 360.0), z));
  }
  return out;
}

}  // namespace tfm
