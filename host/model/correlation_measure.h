// The correlation measures as data (DESIGN.md "Ensembles and correlation fields"): names,
// parameters and their checks, and a caller's member-major ensemble. GPU-free: file formats, the
// CPU references and the kernels (kernels/correlation.h) share them. The conventions every measure
// follows are stated in kernels/correlation.h.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace tfm {

enum class CorrelationMeasure {
  Pearson,        // sample correlation coefficient
  Spearman,       // Pearson of fractional ranks (ties get the mean rank)
  Kendall,        // tau-b with every tie term (scipy.stats.kendalltau's default), O(M log M)
  MiBinned,       // mutual information (nats), `bins` equal-width bins over each series' min..max
  MiKraskov,      // Kraskov-Stoegbauer-Grassberger estimator 1, max-norm, `k` neighbours (nats)
  MiCoefficient,  // sqrt(1 - exp(-2 max(MI, 0))) of the Kraskov estimate, in [0, 1)
};

struct CorrelationParams {
  CorrelationMeasure measure = CorrelationMeasure::Pearson;
  uint32_t bins = 16;  // MiBinned: 2 .. kMaxCorrelationBins
  uint32_t k = 3;      // MiKraskov, MiCoefficient: 1 .. min(member_count - 1, kMaxCorrelationK)
};
constexpr uint32_t kMaxCorrelationBins = 64;
// The kernels keep each point's k nearest distances in registers (shaders/correlation_layout.h).
constexpr uint32_t kMaxCorrelationK = 16;
// One invocation's loops over the members of one voxel stay below the 65535 loop iterations
// llvmpipe allows an invocation (pearson runs 2 M). Measures that sort need workgroup shared
// memory for M values too: CorrelationKernel::shared_memory_bytes.
constexpr uint32_t kMaxCorrelationMembers = 16384;

// "pearson", "spearman", "kendall", "mi-binned", "mi-kraskov", "mi-coefficient".
const char* correlation_measure_name(CorrelationMeasure m);
// Throws std::invalid_argument listing the names when unknown.
CorrelationMeasure parse_correlation_measure(const std::string& name);
std::vector<std::string> correlation_measure_names();
// Whether an infinite member leaves the measure without a value, as NaN does: pearson (the mean is
// infinite), mi-binned (equal-width bins over an infinite range), mi-kraskov and mi-coefficient
// (the estimator's max-norm distances to an infinite value are all infinite: the point has no k
// nearest neighbours; the kernels and the CPU peer, which search sorted values, and the double
// reference, which measures distances, gave three different numbers). Spearman and kendall order
// ±Inf beyond every finite value.
bool needs_finite_members(CorrelationMeasure m);
// Throws std::invalid_argument when params do not suit `member_count` (fewer than 3 members,
// bins or k out of range).
void validate_correlation_params(const CorrelationParams& params, uint32_t member_count);

// A member-major ensemble held by the caller (see above).
struct EnsembleView {
  const float* values = nullptr;
  uint32_t member_count = 0;
  uint64_t voxel_count = 0;
  float at(uint32_t member, uint64_t voxel) const { return values[member * voxel_count + voxel]; }
};

// The series of `ens` at one voxel (member_count values).
std::vector<float> ensemble_series(const EnsembleView& ens, uint64_t voxel);

}  // namespace tfm
