// Runs every solver on one problem and tabulates the results.
#include "normal_equations_cpu.h"
#include "solver_comparison.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "box_qp.h"
#include "normal_equations.h"

namespace tfm {
namespace {

// run_optimize's own phases around the solver's.
bool is_pipeline_phase(const std::string& name) {
  return name == "upload" || name == "loss before" || name == "loss after";
}

Eigen::MatrixX4d as_matrix(const TransferFunction& tf) {
  Eigen::MatrixX4d x(Eigen::Index(tf.size()), 4);
  for (size_t j = 0; j < tf.size(); ++j)
    for (int c = 0; c < 4; ++c) x(Eigen::Index(j), c) = tf.rgba[j][size_t(c)];
  return x;
}

std::string format_ms(double ms) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(ms < 10 ? 2 : (ms < 1000 ? 1 : 0)) << ms;
  return os.str();
}

std::string format_g(double v, int digits = 3) {
  std::ostringstream os;
  os << std::setprecision(digits) << v;
  return os.str();
}

}  // namespace

ComparisonResult compare_solvers(Context& ctx, const OptimizeRequest& request, std::vector<std::string> solvers,
                                 const std::function<void(const ComparisonRow&, size_t, size_t)>& on_row) {
  if (solvers.empty()) {
    solvers = solver_names();
    // The image-based solver optimizes renderings, not voxel colours, and takes minutes at its
    // defaults: name it explicitly to include it.
    solvers.erase(std::remove(solvers.begin(), solvers.end(), "diffdvr"), solvers.end());
  }
  for (const std::string& s : solvers)
    if (!solver_registry().count(s)) throw std::runtime_error("unknown solver '" + s + "'");
  solvers.erase(std::remove(solvers.begin(), solvers.end(), "qp"), solvers.end());
  solvers.insert(solvers.begin(), "qp");

  ComparisonResult out;
  out.device = ctx.device_name();
  out.tf_size = request.tf_size;
  // The box-constrained problem every result is checked against, from the double-precision CPU
  // assembly (independent of the GPU kernels the solvers use); built after the first run, which
  // resolves the field ranges.
  NormalEquations eq;
  Tridiagonal h;
  Eigen::MatrixX4d x_qp;
  for (const std::string& name : solvers) {
    ComparisonRow row;
    row.solver = name;
    OptimizeRequest req = request;
    req.solver = name;
    OptimizeResult r;
    try {
      r = run_optimize(ctx, req);
    } catch (const std::exception& e) {
      if (name == "qp") throw;
      row.error = e.what();
      out.rows.push_back(row);
      if (on_row) on_row(out.rows.back(), out.rows.size(), solvers.size());
      continue;
    }
    if (name == "qp") {
      out.voxels = r.voxels_total;
      out.voxels_with_data = r.after.voxels;
      out.rmse_reference_tf = r.before.rmse();
      eq = assemble_normal_equations_cpu(request.ref->values, request.field->values,
                                         make_mapping(r.ref_range, uint32_t(request.ref_tf.size())),
                                         make_mapping(r.field_range, request.tf_size), request.ref_tf);
      h = regularized_matrix(eq, absolute_regularization(eq, request.settings.solve));
      x_qp = as_matrix(r.tf);
    }
    for (const PhaseTime& p : r.phases)
      if (!is_pipeline_phase(p.name)) row.phases.push_back(p), row.total_ms += p.wall_ms;
    if (r.details.contains("iterations")) row.iterations = r.details["iterations"].get<int64_t>();
    row.rmse = r.after.rmse();
    row.mae = r.after.mae();
    const Eigen::MatrixX4d x = as_matrix(r.tf);
    row.max_diff_to_qp = (x - x_qp).cwiseAbs().maxCoeff();
    for (int c = 0; c < 4; ++c) row.kkt = std::max(row.kkt, box_kkt_residual(h, eq.rhs.col(c), x.col(c)));
    // Solvers that keep x in the box say how in details["box"]; the others clamp their result.
    row.box = r.details.value("box", "clamped " + std::to_string(r.details.value("clamped_values", 0u)));
    row.warnings = r.warnings;
    row.details = r.details;
    out.rows.push_back(row);
    if (on_row) on_row(out.rows.back(), out.rows.size(), solvers.size());
  }
  return out;
}

nlohmann::json ComparisonResult::to_json() const {
  nlohmann::json j;
  j["device"] = device;
  j["voxels"] = voxels;
  j["voxels_with_data"] = voxels_with_data;
  j["tf_size"] = tf_size;
  j["voxel_rmse_reference_tf"] = rmse_reference_tf;
  j["reference_solver"] = "qp";
  auto rows_json = nlohmann::json::array();
  for (const ComparisonRow& r : rows) {
    nlohmann::json rj{{"solver", r.solver}};
    if (!r.error.empty()) {
      rj["error"] = r.error;
      rows_json.push_back(rj);
      continue;
    }
    auto phases = nlohmann::json::array();
    for (const PhaseTime& p : r.phases) {
      nlohmann::json pj{{"name", p.name}, {"wall_ms", p.wall_ms}};
      if (p.gpu_ms >= 0) pj["gpu_ms"] = p.gpu_ms;
      phases.push_back(pj);
    }
    rj["phases"] = phases;
    rj["total_ms"] = r.total_ms;
    rj["iterations"] = r.iterations >= 0 ? nlohmann::json(r.iterations) : nlohmann::json(nullptr);
    rj["voxel_rmse"] = r.rmse;
    rj["voxel_mae"] = r.mae;
    rj["max_diff_to_qp"] = r.max_diff_to_qp;
    rj["box"] = r.box;
    rj["kkt_residual"] = r.kkt;
    rj["warnings"] = r.warnings;
    rj["details"] = r.details;
    rows_json.push_back(rj);
  }
  j["rows"] = rows_json;
  return j;
}

void ComparisonResult::print_table(std::ostream& os) const {
  os << "tfmatch solvers on " << device << ": " << voxels << " voxels (" << voxels_with_data
     << " with data), TF entries " << tf_size << "\n"
     << "voxel RMSE with the reference TF: " << format_g(rmse_reference_tf, 5) << "\n\n";
  const std::vector<std::string> header = {"solver", "total ms", "phases (ms)", "iters", "voxel RMSE",
                                           "max|x-x_qp|", "box", "KKT"};
  std::vector<std::vector<std::string>> cells;
  for (const ComparisonRow& r : rows) {
    if (!r.error.empty()) {
      cells.push_back({r.solver, "-", "error: " + r.error, "", "", "", "", ""});
      continue;
    }
    std::string phases;
    for (const PhaseTime& p : r.phases) phases += (phases.empty() ? "" : " + ") + p.name + " " + format_ms(p.wall_ms);
    cells.push_back({r.solver, format_ms(r.total_ms), phases, r.iterations >= 0 ? std::to_string(r.iterations) : "-",
                     [&] {
                       std::ostringstream v;
                       v << std::fixed << std::setprecision(6) << r.rmse;
                       return v.str();
                     }(),
                     format_g(r.max_diff_to_qp, 2), r.box, format_g(r.kkt, 2)});
  }
  std::vector<size_t> width(header.size());
  for (size_t c = 0; c < header.size(); ++c) {
    width[c] = header[c].size();
    for (const auto& row : cells) width[c] = std::max(width[c], row[c].size());
  }
  auto print_row = [&](const std::vector<std::string>& row) {
    for (size_t c = 0; c < row.size(); ++c) {
      const bool right = c == 1 || c == 3 || c == 4 || c == 5 || c == 7;
      os << (right ? std::right : std::left) << std::setw(int(width[c])) << row[c] << (c + 1 < row.size() ? "  " : "");
    }
    os << "\n";
  };
  print_row(header);
  print_row([&] {
    std::vector<std::string> rule;
    for (size_t w : width) rule.push_back(std::string(w, '-'));
    return rule;
  }());
  for (const auto& row : cells) print_row(row);
  os << std::left;
  for (const ComparisonRow& r : rows)
    for (const std::string& w : r.warnings) os << "warning (" << r.solver << "): " << w << "\n";
}

}  // namespace tfm
