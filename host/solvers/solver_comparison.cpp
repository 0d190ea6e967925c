// Runs every solver on one problem and tabulates the results.
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/solvers/solver_comparison.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "tfmatch/solvers/box_qp.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {
namespace {

// A block of at most 8 voxels a side from the middle of `v` (where a field with a mask or missing
// rim has data), with `v`'s name.
Volume middle_block(const Volume& v) {
  Volume b;
  b.name = v.name;
  b.spacing = v.spacing;
  std::array<uint64_t, 3> first{};
  for (size_t a = 0; a < 3; ++a) {
    b.dims[a] = std::min<uint64_t>(v.dims[a], 8);
    first[a] = (v.dims[a] - b.dims[a]) / 2;
  }
  b.values.reserve(b.voxel_count());
  for (uint64_t z = 0; z < b.dims[2]; ++z)
    for (uint64_t y = 0; y < b.dims[1]; ++y)
      for (uint64_t x = 0; x < b.dims[0]; ++x) b.values.push_back(v.at(first[0] + x, first[1] + y, first[2] + z));
  return b;
}

// Kernels are created at their first use, so the solver run first (qp) paid for the pipelines
// the others share: on lavapipe its "assemble" took 140 ms against normal-equations' 1 ms on the
// same system. Each solver runs once, untimed, on a block of the fields first; a block that
// cannot be solved (no data there, a constant block) only leaves creation to the timed run.
void create_kernels_first(Context& ctx, const OptimizeRequest& request, const ComparisonPlan& plan) {
  const Volume ref = middle_block(*request.ref), field = middle_block(*request.field);
  for (size_t i = 0; i < plan.solvers.size(); ++i) {
    if (require_solver(plan.solvers[i]).image_based()) continue;  // renders full pictures: not cheap
    OptimizeRequest req = request;
    req.ref = &ref;
    req.field = &field;
    req.solver = plan.solvers[i];
    req.settings = plan.settings[i];
    req.voxel_mae = true;
    try {
      (void)run_optimize(ctx, req);
    } catch (const std::exception&) {
      // The timed run reports what is wrong with the problem itself.
    }
  }
}

// run_optimize's own phases around the solver's.
bool is_pipeline_phase(const std::string& name) {
  return name == "upload" || name == "assemble for loss" || name == "loss before" || name == "loss after" ||
         name == "voxel MAE";
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

ComparisonPlan plan_comparison(const SolverSettings& settings, std::vector<std::string> solvers) {
  const bool defaults = solvers.empty();
  if (defaults) {
    // Image-based solvers optimize renderings, not voxel colours, and take minutes at their
    // defaults: name them explicitly to include them.
    for (const auto& s : tfm::solvers())
      if (!s->image_based()) solvers.emplace_back(s->name());
  }
  for (const std::string& s : solvers) require_solver(s);
  solvers.erase(std::remove(solvers.begin(), solvers.end(), "qp"), solvers.end());
  solvers.insert(solvers.begin(), "qp");
  // Every option must be some chosen solver's (of the whole default list: an option of a solver
  // that cannot run here is still a known option); each solver gets its own.
  check_options_apply(settings, solvers);
  ComparisonPlan plan;
  if (defaults)
    std::erase_if(solvers, [&](const std::string& name) {
      std::string why = require_solver(name).unavailable();
      if (why.empty()) return false;
      plan.skipped.emplace_back(name, std::move(why));
      return true;
    });
  for (const std::string& name : solvers) {
    const Solver& solver = require_solver(name);
    const std::vector<SolverOption> declared = solver.options();
    SolverSettings own = settings;
    std::erase_if(own.extra, [&](const auto& option) {
      return std::none_of(declared.begin(), declared.end(), [&](const SolverOption& o) { return o.name == option.first; });
    });
    // Shared options a solver does not honour (--ridge for diffdvr) stay at their defaults for it.
    const SolverConstraints honours = solver.constraints();
    const SolveOptions defaults;
    if (!honours.ridge) own.solve.ridge = defaults.ridge;
    if (!honours.smooth) own.solve.smooth = defaults.smooth;
    if (!honours.factorization) own.solve.factorization = defaults.factorization;
    parse_solver_args(solver, own);  // bad values fail before anything runs
    plan.solvers.push_back(name);
    plan.settings.push_back(std::move(own));
  }
  return plan;
}

ComparisonResult compare_solvers(Context& ctx, const OptimizeRequest& request, std::vector<std::string> names,
                                 const std::function<void(const ComparisonRow&, size_t, size_t)>& on_row) {
  const ComparisonPlan plan = plan_comparison(request.settings, std::move(names));
  const std::vector<std::string>& solvers = plan.solvers;
  ComparisonResult out;
  out.skipped = plan.skipped;
  out.device = ctx.device_name();
  out.tf_size = request.tf_size;
  // The box-constrained problem every result is checked against, from the double-precision CPU
  // assembly (independent of the GPU kernels the solvers use); built after the first run, which
  // resolves the field ranges.
  NormalEquations eq;
  Tridiagonal h;
  Eigen::MatrixX4d x_qp;
  create_kernels_first(ctx, request, plan);
  for (size_t i = 0; i < solvers.size(); ++i) {
    const std::string& name = solvers[i];
    ComparisonRow row;
    row.solver = name;
    OptimizeRequest req = request;
    req.solver = name;
    req.settings = plan.settings[i];
    req.voxel_mae = true;  // the table's MAE column
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
    row.tf = r.tf;
    const Eigen::MatrixX4d x = as_matrix(r.tf);
    row.max_diff_to_qp = (x - x_qp).cwiseAbs().maxCoeff();
    for (int c = 0; c < 4; ++c) row.kkt = std::max(row.kkt, box_kkt_residual(h, eq.rhs.col(c), x.col(c)));
    // Solvers that keep x in the box say how in details["box"]; the others clamp their result.
    const DetailValue* box = r.details.find("box");
    const DetailValue* clamped = r.details.find("clamped_values");
    row.box = box ? box->get<std::string>() : "clamped " + std::to_string(clamped ? clamped->get<uint32_t>() : 0u);
    row.warnings = r.warnings;
    row.details = r.details;
    out.rows.push_back(row);
    if (on_row) on_row(out.rows.back(), out.rows.size(), solvers.size());
  }
  return out;
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
  for (const auto& [solver, why] : skipped) os << "not run: " << solver << " (" << why << ")\n";
  for (const ComparisonRow& r : rows)
    for (const std::string& w : r.warnings) os << "warning (" << r.solver << "): " << w << "\n";
}

}  // namespace tfm
