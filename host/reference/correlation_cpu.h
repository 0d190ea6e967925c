// Double-precision CPU references of the correlation measures of kernels/correlation.h, written
// from the definitions (not from the GPU algorithms) so the kernels can be checked against them,
// and a multi-threaded CPU implementation of the same methods for the benchmark.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "tfmatch/model/correlation_measure.h"

namespace tfm {

// One pair of series of equal length (NaN handling and constant series as in correlation.h).
double pearson_cpu(std::span<const double> x, std::span<const double> y);
double spearman_cpu(std::span<const double> x, std::span<const double> y);
double kendall_tau_b_cpu(std::span<const double> x, std::span<const double> y);  // O(M^2), by definition
double mutual_information_binned_cpu(std::span<const double> x, std::span<const double> y, uint32_t bins);
double mutual_information_kraskov_cpu(std::span<const double> x, std::span<const double> y, uint32_t k);
double correlation_cpu(std::span<const double> x, std::span<const double> y, const CorrelationParams& params);

// The whole field by the reference definitions above (slow; for tests on small grids).
std::vector<double> correlation_field_reference(const EnsembleView& ens, std::span<const float> reference,
                                                const CorrelationParams& params);

// The whole field with `threads` CPU threads (0: all cores) using the fast algorithms (Kendall by
// merge-sort inversion counting, O(M log M)), float results; the benchmark's CPU peer.
std::vector<float> correlation_field_cpu(const EnsembleView& ens, std::span<const float> reference,
                                         const CorrelationParams& params, unsigned threads = 0);

}  // namespace tfm
