#include "tfmatch/reference/irls_cpu.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tfmatch/reference/residual_map_cpu.h"

namespace tfm {

IrlsPassCpu irls_pass_cpu(std::span<const float> ref, std::span<const float> opt, const FieldMapping& ref_map,
                          const FieldMapping& opt_map, std::span<const float> ref_tf, std::span<const float> x,
                          const std::array<float, 4>& delta) {
  const uint32_t n = opt_map.tf_size;
  if (ref.size() != opt.size() || n < 2 || x.size() != size_t(n) * 4 || ref_tf.size() != size_t(ref_map.tf_size) * 4)
    throw std::invalid_argument("irls_pass_cpu: fields, TF or x of mismatched sizes");
  for (float d : delta)
    if (!(d > 0.0f)) throw std::invalid_argument("irls_pass_cpu: delta must be > 0");
  IrlsPassCpu r;
  for (int c = 0; c < 4; ++c) {
    for (auto* v : {&r.diag[c], &r.rhs[c], &r.diag_bound[c], &r.rhs_bound[c]}) v->assign(n, 0.0);
    for (auto* v : {&r.off[c], &r.off_bound[c]}) v->assign(n - 1, 0.0);
  }
  const double truncation = std::ldexp(1.0, -32);
  for (size_t i = 0; i < ref.size(); ++i) {
    double b[4];
    uint32_t j;
    float tf;
    if (!tf_colour_cpu(ref_tf, ref_map, ref[i], b) || !tf_coordinate(opt[i], opt_map, j, tf)) continue;
    const double t = tf;
    for (int c = 0; c < 4; ++c) {
      const double e = (1.0 - t) * x[4 * j + c] + t * x[4 * (j + 1) + c] - b[c];
      const double d = delta[c];
      const double w = d / std::max(std::abs(e), d);
      const double rel = 1e-6 / std::max(std::abs(e), d) + std::ldexp(1.0, -22);
      auto add = [&](std::vector<double>& sum, std::vector<double>& bound, uint32_t k, double term) {
        sum[k] += term;
        bound[k] += term * rel + truncation;
      };
      add(r.diag[c], r.diag_bound[c], j, (1.0 - t) * (1.0 - t) * w);
      add(r.diag[c], r.diag_bound[c], j + 1, t * t * w);
      if (j + 1 < n) add(r.off[c], r.off_bound[c], j, (1.0 - t) * t * w);
      add(r.rhs[c], r.rhs_bound[c], j, (1.0 - t) * w * b[c]);
      add(r.rhs[c], r.rhs_bound[c], j + 1, t * w * b[c]);
      r.l1[c] += std::abs(e);
      r.l1_bound[c] += 1e-6 + truncation;
    }
  }
  return r;
}

}  // namespace tfm
