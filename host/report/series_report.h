// The report of a series fit (`tfmatch optimize --report DIR` with several fields): the reference
// rendered with its TF; each field with the reference TF and with its fitted TF, in a grid; the
// voxel RMSE and image PSNR over the series, before and after, as plots; the fitted TFs overlaid;
// series.json and an index.html showing it all.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/solvers/series_optimize.h"

namespace tfm {

struct SeriesReportInputs {
  const Volume& ref;
  const TransferFunction& ref_tf;
  const SeriesResult& result;
  RenderSettings settings;              // one camera and optical model for every rendering
  std::vector<std::string> labels;      // one per field, as the user named it
  std::function<Volume(size_t)> load_field;  // field i again (rendered one at a time)
  std::string title = "tfmatch series report";
  bool histogram_log = true;  // TF plots: log(1 + count) bars, else counts
  std::string command_line, version;
};

struct SeriesReportSummary {
  std::vector<ImageMetrics> before, after;  // per field: reference image vs the field with each TF
  std::filesystem::path index;              // index.html
  std::vector<std::string> files;           // every file written, relative to the directory
};

// Renders, measures and writes the report into `dir` inside the caller's OutputBatch (or one of
// its own). Throws std::runtime_error for unusable input or a file that cannot be written.
SeriesReportSummary write_series_report(Context& ctx, const SeriesReportInputs& inputs, const std::filesystem::path& dir);

// The names write_series_report() writes for `fields` fields (for FilePlan::output_directory).
std::vector<std::string> series_report_file_names(size_t fields);

// Lines over the fields (x: field index), each a named series of values in its colour, on a
// linear axis with round ticks and a legend; NaN values are left out. Throws
// std::invalid_argument for no lines, no points or a plot smaller than 200 x 120 pixels.
struct PlotLine {
  std::string name;
  Rgb8 colour;
  std::vector<double> values;
};
Image plot_series_lines(const std::vector<PlotLine>& lines, uint32_t width, uint32_t height, const std::string& title,
                        const std::string& x_label);

// The TFs overlaid: each TF's opacity curve in a colour of its own over the TF coordinate
// (0 = each field's range's low end, 1 its high end), with a value axis where every field shares
// one range (`shared_range`), and beneath, one strip per TF of its colours (labelled with its
// index). Throws std::invalid_argument for no TFs or a small plot.
Image plot_tf_overlay(const std::vector<TransferFunction>& tfs, uint32_t width, const std::string& title,
                      const std::optional<FieldRange>& shared_range = std::nullopt);

}  // namespace tfm
