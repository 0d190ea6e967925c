// CPU reference of the residual-map kernel (host/reference/residual_map_cpu.h).
#include "tfmatch/reference/residual_map_cpu.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tfm {

bool tf_colour_cpu(std::span<const float> tf, const FieldMapping& map, float v, double out[4]) {
  uint32_t j;
  float w;
  if (!tf_coordinate(v, map, j, w)) return false;
  for (int c = 0; c < 4; ++c)
    out[c] = std::clamp((1.0 - double(w)) * tf[4 * j + c] + double(w) * tf[4 * (j + 1) + c], 0.0, 1.0);
  return true;
}

std::vector<double> residual_map_cpu(std::span<const float> ref, std::span<const float> opt,
                                     std::span<const float> ref_tf, const FieldMapping& ref_map,
                                     std::span<const float> opt_tf, const FieldMapping& opt_map) {
  if (ref.size() != opt.size()) throw std::invalid_argument("residual_map_cpu: fields differ in size");
  if (ref_tf.size() != 4 * size_t(ref_map.tf_size) || opt_tf.size() != 4 * size_t(opt_map.tf_size))
    throw std::invalid_argument("residual_map_cpu: a TF table does not match its mapping");
  std::vector<double> out(ref.size(), 0.0);
  for (size_t i = 0; i < ref.size(); ++i) {
    double b[4], v[4];
    if (!tf_colour_cpu(ref_tf, ref_map, ref[i], b) || !tf_colour_cpu(opt_tf, opt_map, opt[i], v)) continue;
    const double pb[4] = {b[0] * b[3], b[1] * b[3], b[2] * b[3], b[3]};
    const double pv[4] = {v[0] * v[3], v[1] * v[3], v[2] * v[3], v[3]};
    double s = 0.0;
    for (int c = 0; c < 4; ++c) s += (pb[c] - pv[c]) * (pb[c] - pv[c]);
    out[i] = std::sqrt(s);
  }
  return out;
}

}  // namespace tfm
