// The solver flags of `optimize`, `demo` and `solvers`, generated from the solver registry
// (host/solvers/solver.h): one flag per option name, shared by the solvers that declare it,
// with help naming those solvers; and the list of solvers for help pages.
#pragma once

#include <map>
#include <string>

#include <CLI/CLI.hpp>

namespace tfm::cli {

// Adds every option of every solver to `sub`. A given value is stored as text under its name
// (without dashes) in `values`, which must outlive parsing; parse_solver_args later checks it
// against the chosen solver (an option of another solver is an error naming that solver).
void add_solver_options(CLI::App* sub, std::map<std::string, std::string>& values);

// "cgls, diffdvr, ...": the solver names, for --solver's help.
std::string solver_name_list();

// Each solver with its summary, box handling and options, for a subcommand's footer.
std::string solver_descriptions();

}  // namespace tfm::cli
