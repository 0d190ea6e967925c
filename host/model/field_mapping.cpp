// Field range resolution and the float32 TF mapping.
#include "tfmatch/model/field_mapping.h"

#include <algorithm>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "tfmatch/model/parallel_parts.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

namespace {

// Below this many values a pass runs on the calling thread (a thread costs ~50 us to start).
constexpr size_t kMinPart = size_t(1) << 20;

constexpr size_t kLanes = 16;
constexpr float kMaxFloat = std::numeric_limits<float>::max(), kInf = std::numeric_limits<float>::infinity();

// Runs lane(j, x) over v[0, whole) in groups of kLanes values (x = v[i + j], lane j of the group),
// and empty() after every 2^20 groups, before a lane's 32-bit counts could wrap; returns `whole`,
// the values it took (the rest, fewer than kLanes, are the caller's). Branch-free lane bodies keep
// kLanes independent accumulators each, so the compiler vectorizes the loop at -O2.
template <class Lane, class Empty>
size_t in_lanes(const float* v, size_t n, Lane lane, Empty empty) {
  const size_t whole = n - n % kLanes;
  for (size_t i = 0; i < whole;) {
    const size_t end = std::min(whole, i + (kLanes << 20));
    for (; i < end; i += kLanes)
      for (size_t j = 0; j < kLanes; ++j) lane(j, v[i + j]);
    empty();
  }
  return whole;
}

// finite_stats() of one part: non-finite values become +-inf before the min and max instead of
// a condition inside them (2.6x faster than that on 41 M voxels).
FiniteStats part_stats(const float* v, size_t n) {
  float lo[kLanes], hi[kLanes];
  uint32_t bad[kLanes];
  std::fill_n(lo, kLanes, kInf);
  std::fill_n(hi, kLanes, -kInf);
  std::fill_n(bad, kLanes, 0u);
  uint64_t non_finite = 0;
  const size_t whole = in_lanes(
      v, n,
      [&](size_t j, float x) {
        const bool finite = std::fabs(x) <= kMaxFloat;  // false for NaN and infinities
        const float x_lo = finite ? x : kInf, x_hi = finite ? x : -kInf;
        lo[j] = x_lo < lo[j] ? x_lo : lo[j];
        hi[j] = x_hi > hi[j] ? x_hi : hi[j];
        bad[j] += finite ? 0u : 1u;
      },
      [&] {
        for (size_t j = 0; j < kLanes; ++j) non_finite += std::exchange(bad[j], 0u);
      });
  for (size_t i = whole; i < n; ++i) {
    const float x = v[i];
    if (std::fabs(x) <= kMaxFloat)
      lo[0] = std::min(lo[0], x), hi[0] = std::max(hi[0], x);
    else
      ++non_finite;
  }
  FiniteStats s;
  s.nan = non_finite;
  s.finite = n - non_finite;
  if (s.finite) {
    s.lo = *std::min_element(lo, lo + kLanes);
    s.hi = *std::max_element(hi, hi + kLanes);
  }
  return s;
}

// range_coverage() of one part, against float bounds that decide every float as the double range
// does: x < lo exactly when x < lo_up, the smallest float >= lo (and x > hi when x > hi_down).
RangeCoverage part_coverage(const float* v, size_t n, float lo_up, float hi_down) {
  uint32_t finite[kLanes] = {}, below[kLanes] = {}, above[kLanes] = {};
  RangeCoverage c;
  const size_t whole = in_lanes(
      v, n,
      [&](size_t j, float x) {
        const bool f = std::fabs(x) <= kMaxFloat;
        finite[j] += f ? 1u : 0u;
        below[j] += (f & (x < lo_up)) ? 1u : 0u;
        above[j] += (f & (x > hi_down)) ? 1u : 0u;
      },
      [&] {
        for (size_t j = 0; j < kLanes; ++j) {
          c.finite += std::exchange(finite[j], 0u);
          c.below += std::exchange(below[j], 0u);
          c.above += std::exchange(above[j], 0u);
        }
      });
  for (size_t i = whole; i < n; ++i) {
    const float x = v[i];
    if (!(std::fabs(x) <= kMaxFloat)) continue;
    ++c.finite;
    c.below += x < lo_up;
    c.above += x > hi_down;
  }
  return c;
}

}  // namespace

FiniteStats finite_stats(std::span<const float> values) {
  const std::vector<FiniteStats> parts = in_parts(values.size(), kMinPart, [&](size_t begin, size_t end) {
    return part_stats(values.data() + begin, end - begin);
  });
  FiniteStats s = parts[0];
  for (size_t i = 1; i < parts.size(); ++i) s = merge(s, parts[i]);
  return s;
}

void check_range(const FieldRange& r, const std::string& what) {
  std::ostringstream os;
  os << what << ": range " << r.lo << "," << r.hi;
  const float flo = static_cast<float>(r.lo), fhi = static_cast<float>(r.hi);
  if (!std::isfinite(r.lo) || !std::isfinite(r.hi))
    os << ": both ends must be finite numbers";
  else if (!(r.hi > r.lo))
    os << " is empty or reversed (need lo < hi)";
  else if (!std::isfinite(flo) || !std::isfinite(fhi))
    os << " lies beyond float32, in which the kernels map values (|lo| and |hi| must stay below "
       << std::numeric_limits<float>::max() << ")";
  else if (!std::isfinite(fhi - flo))
    // The kernels take v - lo in float32: over a wider span every value above lo + FLT_MAX became
    // +Inf there and took the TF's top entry (a field in [-3e38, 3e38] rendered mostly one colour).
    os << " is too wide: hi - lo leaves float32, in which the kernels map values (the span must stay below "
       << std::numeric_limits<float>::max() << ")";
  else if (!(fhi > flo) || !std::isfinite(1.0 / (double(fhi) - double(flo))))
    os << " is too narrow: lo and hi are the same number in float32, in which the kernels map values";
  else if (!std::isfinite(static_cast<float>(65535.0 / (double(fhi) - double(flo)))))
    // make_mapping's float32 scale (N - 1) / (hi - lo) for TFs of up to 65536 entries.
    os << " is too narrow: 1 / (hi - lo) leaves float32, in which the kernels map values";
  else
    return;
  throw std::runtime_error(os.str());
}

FiniteStats merge(const FiniteStats& a, const FiniteStats& b) {
  if (a.finite == 0) return {b.lo, b.hi, b.finite, a.nan + b.nan};
  if (b.finite == 0) return {a.lo, a.hi, a.finite, a.nan + b.nan};
  return {std::min(a.lo, b.lo), std::max(a.hi, b.hi), a.finite + b.finite, a.nan + b.nan};
}

FieldRange resolve_range(std::span<const float> values, const FieldRange* user, const std::string& what) {
  if (user) {
    check_range(*user, what);
    return *user;
  }
  return resolve_range(finite_stats(values), nullptr, what);
}

FieldRange resolve_range(const FiniteStats& s, const FieldRange* user, const std::string& what) {
  if (user) {
    check_range(*user, what);
    return *user;
  }
  if (s.finite == 0) throw std::runtime_error(what + ": the field has no finite value");
  if (s.hi == s.lo) {
    std::ostringstream os;
    os << what << ": the field is constant (every finite value is " << s.lo
       << "), so it has no range of its own to map the TF over; give it one (" << parameter("ref-range") << ", "
       << parameter("field-range") << " or " << parameter("range") << ")";
    throw std::runtime_error(os.str());
  }
  // The data's own range must be one the kernels can map too (a field of values near 1e-40 is too
  // narrow, one spanning [-3e38, 3e38] too wide): said here, with the field's name, rather than
  // by make_mapping without it.
  check_range({s.lo, s.hi}, what + " (its finite min/max; give it a range to map it)");
  return {s.lo, s.hi};
}

RangeCoverage range_coverage(std::span<const float> values, const FieldRange& range) {
  // Float bounds with the double comparisons' answers (part_coverage); ends beyond float32 become
  // infinities, below or above every finite float as the double ends are.
  float lo_up = static_cast<float>(range.lo), hi_down = static_cast<float>(range.hi);
  if (double(lo_up) < range.lo) lo_up = std::nextafter(lo_up, std::numeric_limits<float>::infinity());
  if (double(hi_down) > range.hi) hi_down = std::nextafter(hi_down, -std::numeric_limits<float>::infinity());
  RangeCoverage c;
  for (const RangeCoverage& part : in_parts(values.size(), kMinPart, [&](size_t begin, size_t end) {
         return part_coverage(values.data() + begin, end - begin, lo_up, hi_down);
       }))
    c += part;
  return c;
}

std::string check_range_coverage(std::span<const float> values, const FieldRange& range, const std::string& what,
                                 const std::string& source, bool allow) {
  const RangeCoverage c = range_coverage(values, range);
  if (c.finite && !(c.outside_fraction() > kRangeWarnFraction)) return "";
  return check_range_coverage(c, finite_stats(values), range, what, source, allow);
}

std::string check_range_coverage(const RangeCoverage& c, const FiniteStats& s, const FieldRange& range,
                                 const std::string& what, const std::string& source, bool allow) {
  // As without a given range (resolve_range): a field of NaN and infinities has nothing a range
  // could be checked against, nor a value to map.
  if (c.finite == 0) throw std::runtime_error(what + ": the field has no finite value");
  const double f = c.outside_fraction();
  if (!(f > kRangeWarnFraction)) return "";
  std::ostringstream os;
  os.precision(6);
  os << what << ": " << std::fixed << std::setprecision(1) << 100.0 * f << std::defaultfloat << std::setprecision(6)
     << " % of its finite values lie outside " << source << " [" << range.lo << ", " << range.hi << "] (" << c.below
     << " below, " << c.above << " above, of " << c.finite << "; the field spans [" << s.lo << ", " << s.hi
     << "]); they all take the TF's end colours";
  if (f > kRangeErrorFraction) {
    if (!allow)
      throw std::runtime_error(os.str() + ". The range does not fit this field: give its range (" +
                               parameter("ref-range") + ", " + parameter("field-range") + " or " + parameter("range") +
                               ") or pass " + parameter("allow-out-of-range"));
    os << " (" << parameter("allow-out-of-range") << ")";
  }
  return os.str();
}

FieldMapping make_mapping(const FieldRange& range, uint32_t tf_size) {
  check_table_size(tf_size);
  FieldMapping m;
  m.lo = static_cast<float>(range.lo);
  m.scale = static_cast<float>(double(tf_size - 1) / (range.hi - range.lo));
  m.tf_size = tf_size;
  if (!std::isfinite(m.lo) || !std::isfinite(m.scale) || m.scale <= 0.0f) {
    std::ostringstream os;
    os << "range " << range.lo << "," << range.hi << " cannot be mapped to a " << tf_size
       << "-entry transfer function in float32 ("
       << (!std::isfinite(m.lo) ? "beyond float32" : !(m.scale > 0.0f) ? "too wide" : "too narrow") << ")";
    throw std::runtime_error(os.str());
  }
  return m;
}

FieldMapping make_mapping(const FieldRange& range, uint32_t tf_size, const ValueMapping& stored) {
  if (!std::isfinite(stored.scale) || !(stored.scale > 0.0) || !std::isfinite(stored.offset))
    throw std::invalid_argument("value mapping: scale must be finite and > 0, offset finite");
  return make_mapping(FieldRange{(range.lo - stored.offset) / stored.scale, (range.hi - stored.offset) / stored.scale},
                      tf_size);
}

}  // namespace tfm
