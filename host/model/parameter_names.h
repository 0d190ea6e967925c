// How library messages name a caller's parameters. Every parameter a message may point to has one
// name (the name a command-line flag also takes: "max-iterations", "member-dim", "tf-size"), and a
// message writes it through parameter(): plain by default, so an embedder reads "CGLS stopped at
// max-iterations 1000"; a front end installs its own style once at start-up (the `tfmatch` program:
// "--max-iterations"), so its users read the flag they type.
#pragma once

#include <functional>
#include <string>
#include <string_view>

namespace tfm {

// `name` as messages show it in the current style.
std::string parameter(std::string_view name);

// Sets the style (nullptr: the plain name). Not for use while other threads build messages: call
// it at start-up.
void set_parameter_style(std::function<std::string(std::string_view name)> style);

}  // namespace tfm
