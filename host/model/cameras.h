// Camera poses for image-based optimization: uniformly random view directions from a seeded
// generator, or a fixed Fibonacci sphere. Poses are orbit cameras (render_settings.h), so every
// renderer and reference in tfmatch sees exactly the same view.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include "tfmatch/model/render_settings.h"

namespace tfm {

// View directions uniform on the sphere, drawn from std::mt19937_64 seeded with `seed`. The
// doubles are formed from the generator's raw bits (not std::uniform_real_distribution, whose
// output differs between standard libraries), so a seed gives the same poses everywhere.
// Distance and field of view come from `base`.
class RandomCameras {
 public:
  RandomCameras(uint64_t seed, const OrbitCamera& base);
  std::vector<OrbitCamera> next(uint32_t count);

 private:
  double uniform();  // in [0, 1), 53 random bits
  std::mt19937_64 rng_;
  OrbitCamera base_;
};

// `count` directions on a Fibonacci sphere (golden-angle spiral from pole to pole, each point at
// the centre of an equal-area band): near-uniform coverage without randomness.
std::vector<OrbitCamera> fibonacci_cameras(uint32_t count, const OrbitCamera& base);

}  // namespace tfm
