// The correlation measures as data (host/model/correlation_measure.h).
#include "tfmatch/model/correlation_measure.h"

#include <algorithm>
#include <stdexcept>

namespace tfm {

namespace {

struct MeasureName {
  CorrelationMeasure measure;
  const char* name;
};
constexpr MeasureName kMeasureNames[] = {
    {CorrelationMeasure::Pearson, "pearson"},        {CorrelationMeasure::Spearman, "spearman"},
    {CorrelationMeasure::Kendall, "kendall"},        {CorrelationMeasure::MiBinned, "mi-binned"},
    {CorrelationMeasure::MiKraskov, "mi-kraskov"},   {CorrelationMeasure::MiCoefficient, "mi-coefficient"},
};

}  // namespace

const char* correlation_measure_name(CorrelationMeasure m) {
  for (const MeasureName& i : kMeasureNames)
    if (i.measure == m) return i.name;
  throw std::invalid_argument("unknown correlation measure");
}

bool needs_finite_members(CorrelationMeasure m) {
  return m == CorrelationMeasure::Pearson || m == CorrelationMeasure::MiBinned || m == CorrelationMeasure::MiKraskov ||
         m == CorrelationMeasure::MiCoefficient;
}

std::vector<std::string> correlation_measure_names() {
  std::vector<std::string> names;
  for (const MeasureName& i : kMeasureNames) names.emplace_back(i.name);
  return names;
}

CorrelationMeasure parse_correlation_measure(const std::string& name) {
  for (const MeasureName& i : kMeasureNames)
    if (name == i.name) return i.measure;
  std::string list;
  for (const MeasureName& i : kMeasureNames) list += (list.empty() ? "" : ", ") + std::string(i.name);
  throw std::invalid_argument("unknown correlation measure '" + name + "' (measures: " + list + ")");
}

void validate_correlation_params(const CorrelationParams& params, uint32_t member_count) {
  const char* name = correlation_measure_name(params.measure);
  if (member_count < 3 || member_count > kMaxCorrelationMembers)
    throw std::invalid_argument(std::string(name) + ": an ensemble needs 3.." + std::to_string(kMaxCorrelationMembers) +
                                " members (got " + std::to_string(member_count) + ")");
  if (params.measure == CorrelationMeasure::MiBinned && (params.bins < 2 || params.bins > kMaxCorrelationBins))
    throw std::invalid_argument("mi-binned: bins must be 2.." + std::to_string(kMaxCorrelationBins) + " (got " +
                                std::to_string(params.bins) + ")");
  if (params.measure == CorrelationMeasure::MiKraskov || params.measure == CorrelationMeasure::MiCoefficient) {
    const uint32_t max_k = std::min(member_count - 1, kMaxCorrelationK);
    if (params.k < 1 || params.k > max_k)
      throw std::invalid_argument(std::string(name) + ": k must be 1.." + std::to_string(max_k) + " for " +
                                  std::to_string(member_count) + " members (got " + std::to_string(params.k) + ")");
  }
}

std::vector<float> ensemble_series(const EnsembleView& ens, uint64_t voxel) {
  if (voxel >= ens.voxel_count)
    throw std::out_of_range("ensemble_series: voxel " + std::to_string(voxel) + " of " +
                            std::to_string(ens.voxel_count));
  std::vector<float> s(ens.member_count);
  for (uint32_t m = 0; m < ens.member_count; ++m) s[m] = ens.at(m, voxel);
  return s;
}

}  // namespace tfm
