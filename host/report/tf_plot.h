// Transfer-function plots like the paper's figures: the field's histogram (filled, light), the
// opacity curve over it, a colour bar of the TF's RGB beneath, and the range at the ends.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "field_mapping.h"
#include "image.h"
#include "transfer_function.h"

namespace tfm {

// Counts of the finite values in `bins` equal bins over range (values outside are clamped to
// the end bins, as the TF mapping clamps them). NaN is skipped.
std::vector<uint64_t> field_histogram(std::span<const float> values, const FieldRange& range, uint32_t bins);

struct TfPlotOptions {
  uint32_t width = 512;
  uint32_t height = 200;
  std::string title;
  bool log_counts = true;  // bar height log(1 + count): data often has one dominant value
};

// Throws std::invalid_argument when the plot is too small for its axes (< 64 x 80 pixels).
Image plot_transfer_function(const TransferFunction& tf, std::span<const float> values, const FieldRange& range,
                             const TfPlotOptions& options = {});

}  // namespace tfm
