// JSON of solver details, optimize results and solver comparisons.
#include "tfmatch/report/result_json.h"

namespace tfm {
namespace {

nlohmann::json phases_json(const std::vector<PhaseTime>& phases) {
  auto out = nlohmann::json::array();
  for (const PhaseTime& p : phases) {
    nlohmann::json pj{{"name", p.name}, {"wall_ms", p.wall_ms}};
    if (p.gpu_ms >= 0) pj["gpu_ms"] = p.gpu_ms;
    out.push_back(pj);
  }
  return out;
}

}  // namespace

nlohmann::json to_json(const DetailValue& value) {
  return std::visit(
      [](const auto& v) -> nlohmann::json {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, std::monostate>) return nullptr;
        else if constexpr (std::is_same_v<T, Details>) return to_json(v);
        else return v;
      },
      value.storage());
}

nlohmann::json to_json(const Details& details) {
  auto out = nlohmann::json::object();
  for (const auto& [name, value] : details) out[name] = to_json(value);
  return out;
}

nlohmann::json to_json(const OptimizeResult& r) {
  nlohmann::json j;
  j["solver"] = r.solver;
  j["device"] = r.device;
  j["voxels"] = r.voxels_total;
  j["voxels_with_data"] = r.after.voxels;
  j["tf_size"] = r.tf.size();
  j["ref_range"] = {r.ref_range.lo, r.ref_range.hi};
  j["field_range"] = {r.field_range.lo, r.field_range.hi};
  j["voxel_rmse_before"] = r.before.rmse();
  j["voxel_rmse_after"] = r.after.rmse();
  j["voxel_mae_before"] = r.before.mae();
  j["voxel_mae_after"] = r.after.mae();
  j["phases"] = phases_json(r.phases);
  j["warnings"] = r.warnings;
  j["details"] = to_json(r.details);
  return j;
}

nlohmann::json to_json(const ComparisonResult& c) {
  nlohmann::json j;
  j["device"] = c.device;
  j["voxels"] = c.voxels;
  j["voxels_with_data"] = c.voxels_with_data;
  j["tf_size"] = c.tf_size;
  j["voxel_rmse_reference_tf"] = c.rmse_reference_tf;
  j["reference_solver"] = "qp";
  auto rows_json = nlohmann::json::array();
  for (const ComparisonRow& r : c.rows) {
    nlohmann::json rj{{"solver", r.solver}};
    if (!r.error.empty()) {
      rj["error"] = r.error;
      rows_json.push_back(rj);
      continue;
    }
    rj["phases"] = phases_json(r.phases);
    rj["total_ms"] = r.total_ms;
    rj["iterations"] = r.iterations >= 0 ? nlohmann::json(r.iterations) : nlohmann::json(nullptr);
    rj["voxel_rmse"] = r.rmse;
    rj["voxel_mae"] = r.mae;
    rj["max_diff_to_qp"] = r.max_diff_to_qp;
    rj["box"] = r.box;
    rj["kkt_residual"] = r.kkt;
    rj["warnings"] = r.warnings;
    rj["details"] = to_json(r.details);
    rows_json.push_back(rj);
  }
  j["rows"] = rows_json;
  auto skipped = nlohmann::json::array();
  for (const auto& [solver, why] : c.skipped) skipped.push_back({{"solver", solver}, {"reason", why}});
  j["skipped"] = skipped;
  return j;
}

}  // namespace tfm
