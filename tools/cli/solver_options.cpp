// Solver flags and solver help from the registry.
#include "solver_options.h"

#include <algorithm>
#include <cctype>
#include <vector>

#include "tfmatch/solvers/solver.h"

namespace tfm::cli {
namespace {

std::string join(const std::vector<std::string>& items, const std::string& separator) {
  std::string s;
  for (const std::string& item : items) s += (s.empty() ? "" : separator) + item;
  return s;
}

// "what it does; accepted values, default D" for one solver's declaration.
std::string describe(const SolverOption& o) {
  std::string s = o.help;
  if (o.type != OptionType::Flag && o.type != OptionType::Text) s += "; " + o.describe_values();
  const std::string d = o.describe_default();
  if (!d.empty()) s += ", default " + d;
  return s;
}

// The help of flag `name`: one description when every solver that declares it describes it the
// same way, else one per group of solvers; always ending with the solvers it applies to.
std::string flag_help(const std::string& name) {
  std::vector<std::pair<std::string, std::vector<std::string>>> groups;  // description -> solvers
  std::vector<std::string> owners;
  for (const Solver* s : solvers_with_option(name)) {
    owners.emplace_back(s->name());
    for (const SolverOption& o : s->options()) {
      if (o.name != name) continue;
      const std::string d = describe(o);
      auto it = std::find_if(groups.begin(), groups.end(), [&](const auto& g) { return g.first == d; });
      if (it == groups.end()) groups.push_back({d, {std::string(s->name())}});
      else it->second.emplace_back(s->name());
    }
  }
  std::string help;
  if (groups.size() == 1) {
    help = groups[0].first;
    help[0] = char(std::toupper(static_cast<unsigned char>(help[0])));
  } else {
    for (const auto& [d, names] : groups) help += (help.empty() ? "" : " | ") + join(names, ", ") + ": " + d;
  }
  return help + " (solver" + (owners.size() > 1 ? "s: " : ": ") + join(owners, ", ") + ")";
}

// The value placeholder of flag `name` in help: UINT, FLOAT, TEXT, or the choices of every
// solver that declares it ("l2|l1").
std::string flag_type_name(const std::string& name) {
  std::vector<std::string> choices;
  std::string type = "TEXT";
  for (const Solver* s : solvers_with_option(name))
    for (const SolverOption& o : s->options()) {
      if (o.name != name) continue;
      if (o.type == OptionType::Integer) type = "UINT";
      if (o.type == OptionType::Number) type = "FLOAT";
      for (const std::string& c : o.choices)
        if (std::find(choices.begin(), choices.end(), c) == choices.end()) choices.push_back(c);
    }
  return choices.empty() ? type : join(choices, "|");
}

}  // namespace

void add_solver_options(CLI::App* sub, std::map<std::string, std::string>& values) {
  std::vector<std::string> added;
  for (const auto& solver : solvers())
    for (const SolverOption& o : solver->options()) {
      if (std::find(added.begin(), added.end(), o.name) != added.end()) continue;
      added.push_back(o.name);
      const std::string name = o.name;
      CLI::Option* opt = nullptr;
      if (o.type == OptionType::Flag)
        opt = sub->add_flag_function("--" + name, [&values, name](int64_t) { values[name] = "true"; }, flag_help(name));
      else
        opt = sub->add_option_function<std::string>("--" + name, [&values, name](const std::string& v) { values[name] = v; },
                                                    flag_help(name));
      opt->group("Solver options");
      if (o.type != OptionType::Flag) opt->type_name(flag_type_name(name));
    }
}

std::string solver_name_list() { return join(solver_names(), ", "); }

std::string solver_descriptions() {
  std::string s = "Solvers:\n";
  for (const auto& solver : solvers()) {
    const SolverConstraints c = solver->constraints();
    std::vector<std::string> options;
    for (const SolverOption& o : solver->options()) options.push_back("--" + o.name);
    std::vector<std::string> honours;
    if (c.ridge) honours.emplace_back("--ridge");
    if (c.smooth) honours.emplace_back("--smooth");
    s += "  " + std::string(solver->name()) + ": " + std::string(solver->summary()) + "\n      box " +
         box_handling_name(c.box) + (honours.empty() ? "" : "; honours " + join(honours, ", ")) +
         (options.empty() ? "" : "; options " + join(options, ", ")) + "\n";
  }
  return s;
}

}  // namespace tfm::cli
