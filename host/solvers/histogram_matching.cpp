// Quantile functions of histograms and the histogram-matching TF.
#include "tfmatch/solvers/histogram_matching.h"

#include <algorithm>
#include <stdexcept>

namespace tfm {
namespace {

// Cumulative fraction at the B + 1 bin edges: edge 0 = below / n, edge B = (n - above) / n.
std::vector<double> edge_cdf(const FieldHistogram& h) {
  const uint64_t n = h.finite();
  if (n == 0) throw std::invalid_argument("histogram matching: a field has no finite value in its histogram");
  std::vector<double> e(h.bins.size() + 1);
  uint64_t run = h.below;
  e[0] = double(run) / double(n);
  for (size_t k = 0; k < h.bins.size(); ++k) {
    run += h.bins[k];
    e[k + 1] = double(run) / double(n);
  }
  return e;
}

double bin_width(const FieldHistogram& h) { return (h.hi - h.lo) / double(h.bins.size()); }

double cdf_at(const FieldHistogram& h, const std::vector<double>& e, double v) {
  const double t = std::clamp((v - h.lo) / bin_width(h), 0.0, double(h.bins.size()));
  const size_t k = std::min(size_t(t), h.bins.size() - 1);
  const double f = t - double(k);
  return (1.0 - f) * e[k] + f * e[k + 1];
}

double quantile_at(const FieldHistogram& h, const std::vector<double>& e, double q) {
  if (q <= e.front()) return h.lo;
  if (q >= e.back()) return h.hi;
  // First edge whose CDF reaches q; the bin before it holds q's values (non-empty, since the CDF
  // rose across it).
  const size_t k1 = size_t(std::lower_bound(e.begin(), e.end(), q) - e.begin());
  const size_t k = k1 - 1;
  const double f = (q - e[k]) / (e[k1] - e[k]);
  return h.lo + bin_width(h) * (double(k) + f);
}

}  // namespace

double histogram_cdf(const FieldHistogram& h, double v) { return cdf_at(h, edge_cdf(h), v); }

double histogram_quantile(const FieldHistogram& h, double q) { return quantile_at(h, edge_cdf(h), q); }

FieldRange mapping_range(const FieldMapping& m) {
  return {double(m.lo), double(m.lo) + double(m.tf_size - 1) / double(m.scale)};
}

TransferFunction histogram_matching_tf(const FieldHistogram& ref, const FieldHistogram& opt,
                                       const TransferFunction& ref_tf, const FieldMapping& ref_map,
                                       const FieldMapping& opt_map) {
  if (ref_tf.size() != ref_map.tf_size)
    throw std::invalid_argument("histogram matching: the reference TF and its mapping differ in size");
  const std::vector<double> er = edge_cdf(ref), eo = edge_cdf(opt);
  TransferFunction tf;
  tf.rgba.resize(opt_map.tf_size);
  for (uint32_t j = 0; j < opt_map.tf_size; ++j) {
    const double v = double(opt_map.lo) + double(j) / double(opt_map.scale);
    const double u = quantile_at(ref, er, cdf_at(opt, eo, v));
    uint32_t i = 0;
    float w = 0.0f;
    tf_coordinate(float(u), ref_map, i, w);  // u is finite: a quantile of finite values
    for (int c = 0; c < 4; ++c)
      tf.rgba[j][c] = std::clamp((1.0 - w) * ref_tf.rgba[i][c] + double(w) * ref_tf.rgba[i + 1][c], 0.0, 1.0);
  }
  return tf;
}

}  // namespace tfm
