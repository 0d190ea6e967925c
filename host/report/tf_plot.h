// Transfer-function plots like the paper's figures: the field's histogram (filled, light), the
// opacity curve over it, a colour bar of the TF's RGB beneath, value ticks along the field axis,
// opacity ticks on the left, the field's name under the axis and the histogram's scale named.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/model/axis_ticks.h"  // nice_ticks
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// Counts of the finite values in `bins` equal bins over range (values outside are clamped to
// the end bins, as the TF mapping clamps them). NaN is skipped.
std::vector<uint64_t> field_histogram(std::span<const float> values, const FieldRange& range, uint32_t bins);

struct TfPlotOptions {
  uint32_t width = 512;
  uint32_t height = 240;
  std::string title;
  std::string axis_label;  // under the value axis: the field's name (and units where known)
  bool log_counts = true;  // bar height log(1 + count): data often has one dominant value
};

// A field's name for a plot's value axis: its file name with the variable and selectors, without
// folders, and the values' units where the file gives them.
std::string field_label(const Volume& v);

// A value axis under a plot whose [range.lo, range.hi] spans `width` pixels from x = `left`: ticks
// 4 pixels down from `y` at round values, their labels beneath (inside the picture, never
// overlapping). Returns the y below the labels.
int draw_value_ticks(Image& img, int left, int width, int y, const FieldRange& range, Rgb8 tick, Rgb8 text);

// A value axis's caption within `width` pixels: whole where it fits; else the variable part of a
// "FILE:VAR..." name (the file dropped); else as much of its end as fits (fit_text).
std::string axis_caption(const std::string& label, int width);

// Throws std::invalid_argument when the plot is too small for its axes (< 160 x 140 pixels).
Image plot_transfer_function(const TransferFunction& tf, std::span<const float> values, const FieldRange& range,
                             const TfPlotOptions& options = {});

}  // namespace tfm
