// The registry: every solver tfmatch offers, listed here explicitly (no static registration: a
// solver exists because it is in this list, whatever the linker keeps), and those an optional
// component adds by an explicit call (add_solvers: the CUDA solvers' register_cuda_solvers()).
// Each factory is defined in its solver_*.cpp.
#include <algorithm>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>

#include "tfmatch/model/parameter_names.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

std::unique_ptr<Solver> make_cgls_solver();
std::unique_ptr<Solver> make_diffdvr_solver();
std::unique_ptr<Solver> make_eigen_cgls_solver();
std::unique_ptr<Solver> make_eigen_normal_equations_solver();
std::unique_ptr<Solver> make_gradient_descent_solver();
std::unique_ptr<Solver> make_histogram_matching_solver();
std::unique_ptr<Solver> make_irls_solver();
std::unique_ptr<Solver> make_normal_equations_solver();
std::unique_ptr<Solver> make_qp_solver();
namespace {

// What add_solvers() registered, and whether the registry has been built.
struct Extensions {
  std::mutex mutex;
  std::vector<std::function<std::vector<std::unique_ptr<Solver>>()>> makers;
  bool built = false;
};
Extensions& extensions() {
  static Extensions e;
  return e;
}

std::vector<std::unique_ptr<Solver>> make_solvers() {
  std::vector<std::unique_ptr<Solver>> list;
  list.push_back(make_cgls_solver());
  list.push_back(make_diffdvr_solver());
  list.push_back(make_eigen_cgls_solver());
  list.push_back(make_eigen_normal_equations_solver());
  list.push_back(make_gradient_descent_solver());
  list.push_back(make_histogram_matching_solver());
  list.push_back(make_irls_solver());
  list.push_back(make_normal_equations_solver());
  list.push_back(make_qp_solver());
  {
    Extensions& e = extensions();
    std::lock_guard lock(e.mutex);
    e.built = true;
    for (const auto& make : e.makers)
      for (auto& s : make()) list.push_back(std::move(s));
  }
  std::sort(list.begin(), list.end(), [](const auto& a, const auto& b) { return a->name() < b->name(); });
  return list;
}

// Broken declarations are programming errors: names and flags must be unique, and a flag shared
// by several solvers must have one type (the command line has one flag for it).
void check_declarations(const std::vector<std::unique_ptr<Solver>>& list) {
  std::set<std::string_view> names;
  std::map<std::string, OptionType> types;
  for (const auto& s : list) {
    if (!names.insert(s->name()).second) throw std::logic_error("two solvers named " + std::string(s->name()));
    std::set<std::string> own;
    for (const SolverOption& o : s->options()) {
      if (!own.insert(o.name).second)
        throw std::logic_error("solver " + std::string(s->name()) + " declares --" + o.name + " twice");
      if (types.emplace(o.name, o.type).first->second != o.type)
        throw std::logic_error(parameter(o.name) + " has different types in different solvers");
    }
  }
}

}  // namespace

void add_solvers(std::function<std::vector<std::unique_ptr<Solver>>()> make) {
  Extensions& e = extensions();
  std::lock_guard lock(e.mutex);
  if (e.built) throw std::logic_error("add_solvers: the solver registry has already been built");
  e.makers.push_back(std::move(make));
}

const std::vector<std::unique_ptr<Solver>>& solvers() {
  static const std::vector<std::unique_ptr<Solver>> list = [] {
    auto l = make_solvers();
    check_declarations(l);
    return l;
  }();
  return list;
}

}  // namespace tfm
