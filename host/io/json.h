// nlohmann::json for every file of tfmatch and its tests: include this, never
// <nlohmann/json.hpp> directly (the configure's layer check and the test Layers.IncludesPointDown
// refuse that). It defines JSON_ASSERT, which nlohmann::json evaluates where a read has no
// answer — operator[] with a missing key on a const object, above all — as a throw of
// std::logic_error. Its default is assert(), which NDEBUG builds (RelWithDebInfo, the default
// here) turn off, leaving such a read undefined behaviour: garbage or a crash instead of a
// failed test or a clear error. One definition in every file, so nlohmann's inline functions are
// the same everywhere. (A compile definition cannot carry it: CMake drops function-like ones.)
#pragma once

#include <stdexcept>

#include <string>

namespace tfm::detail {
// Not a throw-expression in the macro: nlohmann evaluates JSON_ASSERT in noexcept functions too
// (where a failure ends the program, as assert() would), and GCC warns at each such throw.
[[noreturn]] inline void json_assert_failed(const char* condition) {
  throw std::logic_error(std::string("nlohmann::json: ") + condition +
                         " does not hold (a missing key read from a const object?)");
}
}  // namespace tfm::detail

#define JSON_ASSERT(x) ((x) ? void(0) : ::tfm::detail::json_assert_failed(#x))

#include <nlohmann/json.hpp>

namespace tfm {
// The text of `j` as every file and response of tfmatch writes it: indented by `indent` spaces
// (-1: on one line). Names in it come from the file system, where they need not be UTF-8 (a
// Latin-1 "lat\xe9.raw"), and JSON text must be: a byte that is not UTF-8 becomes U+FFFD instead of
// nlohmann's default, a throw at the end of the run that loses every output.
inline std::string json_text(const nlohmann::json& j, int indent = -1) {
  return j.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}
}  // namespace tfm
