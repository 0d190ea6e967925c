// Solver options: declaration helpers, help text, the central parser and checks; lookups in the
// registry (the list itself is solver_registry.cpp).
#include "tfmatch/solvers/solver.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/parameter_names.h"

namespace tfm {
namespace {

std::string format_number(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

std::string join(const std::vector<std::string>& items, const std::string& separator, const std::string& last) {
  std::string s;
  for (size_t i = 0; i < items.size(); ++i) s += (i == 0 ? "" : (i + 1 == items.size() ? last : separator)) + items[i];
  return s;
}

const char* type_name(OptionType t) {
  switch (t) {
    case OptionType::Integer: return "integer";
    case OptionType::Number: return "number";
    case OptionType::Choice: return "choice";
    case OptionType::Text: return "text";
    case OptionType::Flag: return "flag";
  }
  return "?";
}

// Strict conversions: the whole text must be the number.
bool to_double(const std::string& text, double& out) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text.front()))) return false;
  try {
    size_t used = 0;
    out = std::stod(text, &used);
    return used == text.size();
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

bool parse_option_integer(const std::string& text, uint64_t& out) {
  if (!text.empty() && std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    try {
      out = std::stoull(text);
      return true;
    } catch (const std::exception&) {
      return false;  // beyond 2^64 - 1
    }
  }
  double v = 0.0;
  if (!to_double(text, v) || !(v >= 0.0) || v > 9007199254740992.0 || v != std::floor(v)) return false;
  out = uint64_t(v);
  return true;
}

// ---- SolverOption -----------------------------------------------------------------------------

SolverOption SolverOption::integer(std::string name, uint64_t default_value, uint64_t min, uint64_t max,
                                   std::string help) {
  SolverOption o;
  o.name = std::move(name);
  o.type = OptionType::Integer;
  o.default_value = default_value;
  o.integer_min = min;
  o.integer_max = max;
  o.help = std::move(help);
  return o;
}

SolverOption SolverOption::number(std::string name, double default_value, NumberRange range, std::string help) {
  SolverOption o;
  o.name = std::move(name);
  o.type = OptionType::Number;
  o.default_value = default_value;
  o.range = range;
  o.help = std::move(help);
  return o;
}

SolverOption SolverOption::choice(std::string name, std::string default_value, std::vector<std::string> choices,
                                  std::string help) {
  SolverOption o;
  o.name = std::move(name);
  o.type = OptionType::Choice;
  o.default_value = std::move(default_value);
  o.choices = std::move(choices);
  o.help = std::move(help);
  return o;
}

SolverOption SolverOption::text(std::string name, std::string default_value, std::string help) {
  SolverOption o;
  o.name = std::move(name);
  o.type = OptionType::Text;
  o.default_value = std::move(default_value);
  o.help = std::move(help);
  return o;
}

SolverOption SolverOption::flag(std::string name, std::string help) {
  SolverOption o;
  o.name = std::move(name);
  o.type = OptionType::Flag;
  o.default_value = false;
  o.help = std::move(help);
  return o;
}

std::string SolverOption::describe_values() const {
  switch (type) {
    case OptionType::Integer:
      if (integer_max == std::numeric_limits<uint64_t>::max())
        return integer_min == 0 ? "an integer >= 0" : "an integer >= " + std::to_string(integer_min);
      return "an integer in [" + std::to_string(integer_min) + ", " + std::to_string(integer_max) + "]";
    case OptionType::Number: {
      const bool lo = std::isfinite(range.min), hi = std::isfinite(range.max);
      if (lo && hi)
        return "a number in " + std::string(range.min_open ? "(" : "[") + format_number(range.min) + ", " +
               format_number(range.max) + (range.max_open ? ")" : "]");
      if (lo) return "a number " + std::string(range.min_open ? "> " : ">= ") + format_number(range.min);
      if (hi) return "a number " + std::string(range.max_open ? "< " : "<= ") + format_number(range.max);
      return "a number";
    }
    case OptionType::Choice: return join(choices, ", ", " or ");
    case OptionType::Text: return "text";
    case OptionType::Flag: return "a flag";
  }
  return {};
}

std::string SolverOption::describe_default() const {
  if (!default_help.empty()) return default_help;
  if (type == OptionType::Flag) return {};
  if (const uint64_t* i = std::get_if<uint64_t>(&default_value)) return std::to_string(*i);
  if (const double* d = std::get_if<double>(&default_value)) return format_number(*d);
  if (const std::string* s = std::get_if<std::string>(&default_value)) return *s;
  return {};
}

OptionValue SolverOption::parse(const std::string& text, std::string_view solver) const {
  auto fail = [&]() -> OptionValue {
    throw std::runtime_error(parameter(name) + " of solver " + std::string(solver) + ": expected " + describe_values() +
                             ", got '" + text + "'");
  };
  switch (type) {
    case OptionType::Integer: {
      uint64_t v = 0;
      if (!parse_option_integer(text, v) || v < integer_min || v > integer_max) return fail();
      return v;
    }
    case OptionType::Number: {
      double v = 0.0;
      if (!to_double(text, v) || !std::isfinite(v)) return fail();
      const bool above = range.min_open ? v > range.min : v >= range.min;
      const bool below = range.max_open ? v < range.max : v <= range.max;
      if (!above || !below) return fail();
      return v;
    }
    case OptionType::Choice:
      if (std::find(choices.begin(), choices.end(), text) == choices.end()) return fail();
      return text;
    case OptionType::Text: return text;
    case OptionType::Flag:
      if (text.empty() || text == "true" || text == "1" || text == "on") return true;
      if (text == "false" || text == "0" || text == "off") return false;
      return fail();
  }
  return fail();
}

// ---- SolverArgs -------------------------------------------------------------------------------

const SolverArgs::Entry& SolverArgs::entry(std::string_view name, OptionType type) const {
  auto it = values_.find(name);
  if (it == values_.end())
    throw std::logic_error("solver " + solver_ + " reads option '" + std::string(name) + "' it did not declare");
  if (it->second.type != type)
    throw std::logic_error("solver " + solver_ + " reads option '" + std::string(name) + "' as " + type_name(type) +
                           ", declared as " + type_name(it->second.type));
  if (std::holds_alternative<std::monostate>(it->second.value))
    throw std::logic_error("solver " + solver_ + " reads option '" + std::string(name) + "', which has no value");
  return it->second;
}

uint64_t SolverArgs::integer(std::string_view name) const {
  return std::get<uint64_t>(entry(name, OptionType::Integer).value);
}

double SolverArgs::number(std::string_view name) const { return std::get<double>(entry(name, OptionType::Number).value); }

const std::string& SolverArgs::text(std::string_view name) const {
  auto it = values_.find(name);
  const OptionType type = it != values_.end() && it->second.type == OptionType::Text ? OptionType::Text
                                                                                      : OptionType::Choice;
  return std::get<std::string>(entry(name, type).value);
}

bool SolverArgs::flag(std::string_view name) const { return std::get<bool>(entry(name, OptionType::Flag).value); }

bool SolverArgs::given(std::string_view name) const {
  auto it = values_.find(name);
  return it != values_.end() && it->second.given;
}

bool SolverArgs::has(std::string_view name) const {
  auto it = values_.find(name);
  return it != values_.end() && !std::holds_alternative<std::monostate>(it->second.value);
}

// ---- registry lookups and parsing -------------------------------------------------------------

const char* box_handling_name(BoxHandling box) {
  switch (box) {
    case BoxHandling::Clamped: return "clamped";
    case BoxHandling::Projected: return "projected";
    case BoxHandling::Enforced: return "enforced";
  }
  return "?";
}

const Solver* find_solver(std::string_view name) {
  for (const auto& s : solvers())
    if (s->name() == name) return s.get();
  return nullptr;
}

const Solver& require_solver(std::string_view name) {
  if (const Solver* s = find_solver(name)) return *s;
  throw std::runtime_error("unknown solver '" + std::string(name) + "' (available: " + join(solver_names(), ", ", ", ") +
                           ")");
}

std::vector<std::string> solver_names() {
  std::vector<std::string> names;
  for (const auto& s : solvers()) names.emplace_back(s->name());
  return names;
}

std::vector<const Solver*> solvers_with_option(std::string_view option) {
  std::vector<const Solver*> out;
  for (const auto& s : solvers())
    for (const SolverOption& o : s->options())
      if (o.name == option) out.push_back(s.get());
  return out;
}

namespace {

// Throws when none of `chosen` is among `owners`, the solvers flag --`name` applies to.
void require_owner(const std::string& name, const std::vector<std::string>& owners, const std::vector<std::string>& chosen) {
  if (owners.empty()) throw std::runtime_error("unknown solver option --" + name);
  const bool applies = std::any_of(chosen.begin(), chosen.end(), [&](const std::string& c) {
    return std::find(owners.begin(), owners.end(), c) != owners.end();
  });
  if (!applies)
    throw std::runtime_error(parameter(name) + " applies to solver" + (owners.size() > 1 ? "s " : " ") +
                             join(owners, ", ", ", ") + ", not to " + join(chosen, ", ", ", "));
}

}  // namespace

void check_options_apply(const SolverSettings& settings, const std::vector<std::string>& chosen) {
  for (const auto& [name, value] : settings.extra) {
    std::vector<std::string> owners;
    for (const Solver* s : solvers_with_option(name)) owners.emplace_back(s->name());
    require_owner(name, owners, chosen);
  }
  // The options every solver's SolveOptions carries: given when not at their defaults.
  const SolveOptions defaults;
  const std::pair<const char*, bool SolverConstraints::*> shared[] = {
      {"ridge", &SolverConstraints::ridge}, {"smooth", &SolverConstraints::smooth},
      {"factorization", &SolverConstraints::factorization}};
  const bool given[] = {settings.solve.ridge != defaults.ridge, settings.solve.smooth != defaults.smooth,
                        settings.solve.factorization != defaults.factorization};
  for (size_t i = 0; i < std::size(shared); ++i) {
    if (!given[i]) continue;
    std::vector<std::string> owners;
    for (const auto& s : solvers())
      if (s->constraints().*shared[i].second) owners.emplace_back(s->name());
    require_owner(shared[i].first, owners, chosen);
  }
}

SolverArgs parse_solver_args(const Solver& solver, const SolverSettings& settings) {
  check_options_apply(settings, {std::string(solver.name())});
  SolverArgs args;
  args.solve = settings.solve;
  args.render = settings.render;
  args.solver_ = solver.name();
  const std::vector<SolverOption> options = solver.options();
  for (const SolverOption& o : options) args.values_[o.name] = {o.type, o.default_value, false};
  for (const auto& [name, text] : settings.extra) {
    const auto o = std::find_if(options.begin(), options.end(), [&](const SolverOption& x) { return x.name == name; });
    args.values_[name] = {o->type, o->parse(text, solver.name()), true};
  }
  return args;
}

SolverOutput run_solver(std::string_view name, VoxelProblem& problem, const SolverSettings& settings) {
  const Solver& solver = require_solver(name);
  return solver.solve(problem, parse_solver_args(solver, settings));
}

}  // namespace tfm
