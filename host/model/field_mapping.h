// The field-range convention of DESIGN.md: finite range, value -> TF coordinate, and the float32
// mapping the GPU kernels use (mirrored bit for bit so CPU references see identical weights).
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <string>

#include "tfmatch/shaders/shared_layout.h"  // FieldMapping, the record the kernels take

namespace tfm {

struct FieldRange {
  double lo = 0.0;
  double hi = 1.0;
};

struct FiniteStats {
  double lo = 0.0, hi = 0.0;
  uint64_t finite = 0;
  uint64_t nan = 0;  // non-finite values that count as "no data" (NaN)
};

// Finite min/max and NaN count of a field.
FiniteStats finite_stats(std::span<const float> values);

// finite_stats() of the concatenation of two parts (a field read slab by slab).
FiniteStats merge(const FiniteStats& a, const FiniteStats& b);

// Range of a field: `user` if given (checked by check_range), else the finite min/max. Throws
// std::runtime_error naming `what` when the field has no finite value, is constant (hi == lo), or
// has a min/max check_range refuses.
FieldRange resolve_range(std::span<const float> values, const FieldRange* user, const std::string& what);
// The same from the field's finite_stats() (a field streamed from disk).
FieldRange resolve_range(const FiniteStats& stats, const FieldRange* user, const std::string& what);

// Throws std::runtime_error "<what>: range lo,hi ..." saying what is wrong with a given range:
// an end that is not a finite number, lo >= hi, an end beyond float32 (the kernels map values in
// float32), a span hi - lo beyond float32, or ends float32 cannot tell apart.
void check_range(const FieldRange& range, const std::string& what);

// A range that does not come from the field (a TF file's, or given) may leave values outside;
// they clamp to the TF's end entries. Counts of finite values below and above it.
struct RangeCoverage {
  uint64_t finite = 0, below = 0, above = 0;
  RangeCoverage& operator+=(const RangeCoverage& o) {
    finite += o.finite, below += o.below, above += o.above;
    return *this;
  }
  double outside_fraction() const { return finite ? double(below + above) / double(finite) : 0.0; }
};
RangeCoverage range_coverage(std::span<const float> values, const FieldRange& range);

// Above this fraction of finite values outside, a warning; above the second, an error.
inline constexpr double kRangeWarnFraction = 0.05;
inline constexpr double kRangeErrorFraction = 0.95;

// Checks `range` (described by `source`, e.g. "the reference TF file's range") against the
// field's finite values: returns a warning with the counts below and above when more than 5 %
// lie outside, and throws std::runtime_error when more than 95 % do, unless `allow` (then the
// warning says the check was overridden). Empty when the range fits. Throws too for a field with
// no finite value (NaN and infinities only), as resolve_range() does without a range.
std::string check_range_coverage(std::span<const float> values, const FieldRange& range, const std::string& what,
                                 const std::string& source, bool allow);
// The same from the counts and the field's finite_stats() (a field streamed from disk).
std::string check_range_coverage(const RangeCoverage& coverage, const FiniteStats& stats, const FieldRange& range,
                                 const std::string& what, const std::string& source, bool allow);

FieldMapping make_mapping(const FieldRange& range, uint32_t tf_size);

// How stored numbers become field values, for a field kept in other units (an embedder's unorm16
// or float16 volume, read in place): value = scale * stored + offset, `stored` being what the
// kernels read (the float, the float16, or a unorm's c / (2^b - 1)).
struct ValueMapping {
  double scale = 1.0;
  double offset = 0.0;
};
// The mapping of stored numbers onto the TF of a field whose values `range` maps: the same TF
// coordinates as make_mapping(range, tf_size) gives the values, up to float rounding. Throws
// std::invalid_argument unless scale is finite and > 0, and as make_mapping otherwise.
FieldMapping make_mapping(const FieldRange& range, uint32_t tf_size, const ValueMapping& stored);

// "No data" (DESIGN.md): NaN and ±Inf, which no range maps. Mirror of no_data() in
// shaders/tf_common.glsl.
inline bool no_data(float v) { return !std::isfinite(v); }

// Bit-identical CPU mirror of tf_coordinate() in shaders/tf_common.glsl. Returns false for no
// data (NaN, ±Inf).
inline bool tf_coordinate(float v, const FieldMapping& m, uint32_t& j, float& w) {
  if (no_data(v)) return false;
  // volatile-free: this file is compiled with -ffp-contract=off (host/CMakeLists.txt).
  float x = (v - m.lo) * m.scale;
  float top = float(m.tf_size - 1);
  x = x < 0.0f ? 0.0f : (x > top ? top : x);
  float jf = std::fmin(std::floor(x), float(m.tf_size - 2));
  j = static_cast<uint32_t>(jf);
  w = x - jf;
  return true;
}

}  // namespace tfm
