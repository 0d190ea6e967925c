// Parameter names in library messages (host/model/parameter_names.h).
#include "tfmatch/model/parameter_names.h"

#include <utility>

namespace tfm {
namespace {

std::function<std::string(std::string_view)>& style() {
  static std::function<std::string(std::string_view)> s;
  return s;
}

}  // namespace

std::string parameter(std::string_view name) { return style() ? style()(name) : std::string(name); }

void set_parameter_style(std::function<std::string(std::string_view name)> s) { style() = std::move(s); }

}  // namespace tfm
