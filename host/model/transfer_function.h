// Node-aligned RGBA transfer-function tables (DESIGN.md) (files: host/io/tf_json.h, tf_formats.h).
#pragma once

#include <array>
#include <functional>
#include <span>
#include <optional>
#include <string>
#include <vector>

#include "tfmatch/model/field_mapping.h"

namespace tfm {

using Rgba = std::array<double, 4>;

// The most entries a TF of tfmatch has: the command line's --tf-size bound, and the largest table
// read from control points (2^16).
inline constexpr size_t kMaxTableSize = size_t(1) << 16;

// Throws std::invalid_argument unless a TF of `n` entries is one tfmatch's kernels take:
// 2 <= n <= kMaxTableSize (their accumulators' sizes, 6n + 8 slots, are 32-bit numbers).
void check_table_size(uint64_t n);

struct TransferFunction {
  std::vector<Rgba> rgba;             // entry j at t = j/(N-1), values in [0,1]
  std::optional<FieldRange> range;    // data range the table was made for, if the file says

  size_t size() const { return rgba.size(); }
  // T(t) for t in [0,1] (clamped), linear between entries.
  Rgba eval(double t) const;
  // The same TF sampled at `n` node-aligned entries (exact when n == size()).
  TransferFunction resampled(size_t n) const;
  // Entries as float RGBA (for device upload).
  std::vector<float> as_floats() const;
};

// A colour stop of a colour map: colour (r, g, b) at t, linear between stops (t increasing).
struct ColorStop {
  double t, r, g, b;
};
// N entries whose colours interpolate `stops` and whose opacity is alpha(t) clamped to [0, 1];
// no range. Throws std::invalid_argument for fewer than 2 entries or stops.
TransferFunction tf_from_color_stops(uint32_t n, std::span<const ColorStop> stops, const std::function<double(double)>& alpha);

}  // namespace tfm
