// Contiguous parts of a range run on the hardware's threads: for passes over a whole field in
// memory (its finite min/max, its range coverage) whose partial results combine exactly.
#pragma once

#include <algorithm>
#include <cstddef>
#include <exception>
#include <optional>
#include <thread>
#include <type_traits>
#include <vector>

namespace tfm {

// Splits [0, n) into at most hardware_concurrency() contiguous parts of at least `min_part`
// elements (one part when n is smaller), computes part(begin, end) for each, the first on the
// calling thread and the others on threads of their own, and returns the results in the parts'
// order. The first exception a part throws is rethrown after every part has ended.
template <class Part>
auto in_parts(size_t n, size_t min_part, Part&& part) -> std::vector<std::invoke_result_t<Part&, size_t, size_t>> {
  using Result = std::invoke_result_t<Part&, size_t, size_t>;
  const size_t threads = std::max(1u, std::thread::hardware_concurrency());
  const size_t parts = std::max<size_t>(1, std::min(threads, n / std::max<size_t>(min_part, 1)));
  auto bounds = [&](size_t i) { return n / parts * i + std::min(i, n % parts); };
  std::vector<std::optional<Result>> results(parts);
  std::vector<std::exception_ptr> errors(parts);
  auto run = [&](size_t i) {
    try {
      results[i].emplace(part(bounds(i), bounds(i + 1)));
    } catch (...) {
      errors[i] = std::current_exception();
    }
  };
  {
    // jthreads: should starting one fail, the ones already running are joined before the error
    // leaves (a std::thread still joinable when destroyed ends the program).
    std::vector<std::jthread> helpers;
    helpers.reserve(parts - 1);
    for (size_t i = 1; i < parts; ++i) helpers.emplace_back(run, i);
    run(0);
  }
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
  std::vector<Result> out;
  out.reserve(parts);
  for (auto& r : results) out.push_back(std::move(*r));
  return out;
}

}  // namespace tfm
