// Node-aligned RGBA transfer-function tables (DESIGN.md) and their JSON file format.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "field_mapping.h"

namespace tfm {

using Rgba = std::array<double, 4>;

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

// Reads {"rgba": [[r,g,b,a], ...], "range": [lo, hi]?}. Throws std::runtime_error naming the
// file for unreadable JSON, fewer than 2 entries, rows that are not 4 numbers, values outside
// [0,1] or not finite.
TransferFunction read_tf_json(const std::filesystem::path& path);
TransferFunction parse_tf_json(const std::string& text, const std::string& source_name);
// Writes atomically (temporary file, then rename), so a failure leaves no half-written file.
void write_tf_json(const std::filesystem::path& path, const TransferFunction& tf);
std::string tf_to_json(const TransferFunction& tf);

}  // namespace tfm
