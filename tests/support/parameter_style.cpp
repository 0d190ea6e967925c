// The test program reads library messages as the `tfmatch` program shows them (tools/cli/main.cpp):
// parameters named as the flags that set them, so tests of messages check what users read.
// test_parameter_names.cpp checks the library's own plain style.
#include <string>
#include <string_view>

#include "tfmatch/model/parameter_names.h"

namespace {
// Static initialisation runs before main(), so before any test builds a message.
[[maybe_unused]] const bool styled =
    (tfm::set_parameter_style([](std::string_view name) { return "--" + std::string(name); }), true);
}  // namespace
