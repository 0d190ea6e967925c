// The report of an optimization (`tfmatch optimize --report DIR`, `tfmatch demo`): renderings of
// the reference, of the second field with the reference and the optimized TF, residual maps
// before and after, TF plots, image metrics, metrics.json and an index.html showing it all.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/solvers/optimize.h"

namespace tfm {

// A picture another part adds to the report (DiffDVR's loss curve, say): written as `file`
// (a PNG name inside the report directory) and shown in its own section.
struct ReportFigure {
  std::string title;
  std::string file;
  Image image;
  std::string caption;
};

struct ReportInputs {
  const Volume& ref;
  const Volume& field;
  const TransferFunction& ref_tf;
  const OptimizeResult& result;    // optimized TF, both ranges, voxel losses, solver details
  RenderSettings settings;         // one camera and optical model for every rendering
  std::string title = "tfmatch report";
  // Grid points drawn as red dots on every rendering (correlation reference points); the image
  // metrics are computed on the renderings without them.
  std::vector<GridIndex> markers;
  // Axis-aligned slices (reference, field with each TF, residual after) go through this voxel;
  // when not given, through the first marker, else the grid's middle.
  std::optional<GridIndex> slice_point;
  std::vector<ReportFigure> extra_figures;
  nlohmann::json extra_metrics;    // merged into metrics.json under "extra" when not null
  // Where the two fields are known to differ in structure (1 per voxel of a ground-truth mask, in
  // the fields' order; the demo's changed regions): the report then states how much of the
  // residual lies there, before and after optimization. Empty: not known.
  std::vector<uint8_t> changed_regions;
  // Shown under the title (a streamed run: the pictures are of a downsampled copy).
  std::vector<std::string> notes;
  bool histogram_log = true;       // TF plots: log(1 + count) bars, else counts (each plot says which)
  // Saved with the report (command.txt, the page) so that it can be reproduced.
  std::string command_line;
  std::string version;
  // What reopens the report's inputs (`tfmatch view --report DIR`): written as inputs.json when
  // not null (file specs with absolute paths, ranges, TF size, solver and its options).
  nlohmann::json inputs;
};

struct ReportSummary {
  ImageMetrics before;  // reference image vs the field with the reference TF
  ImageMetrics after;   // reference image vs the field with the optimized TF
  double residual_max_before = 0.0, residual_max_after = 0.0;
  // With ReportInputs::changed_regions: the fraction of the residual map's sum inside them.
  std::optional<double> residual_inside_before, residual_inside_after;
  std::filesystem::path index;  // index.html
  struct Slice {
    std::string file;     // slices_z.png, ...
    std::string caption;  // "z = 12 (level 500 hPa)"
  };
  std::vector<Slice> slices;    // one per axis whose plane is at least 2 x 2 voxels
  GridIndex slice_point{};
  std::vector<std::string> files;  // every file written, relative to the report directory
  // What the pictures themselves say is wrong (renderings nearly all background: their metrics
  // compare empty pictures), on the page beside the run's warnings.
  std::vector<std::string> warnings;
};

// The fraction of `img`'s pixels within 16 of 255 levels of `background` (linear RGB, as the
// renderer's) in every channel: the background and colour too faint to tell from it (a picture of
// pale pink haze on white is nearly empty to a reader).
double background_fraction(const Image& img, const std::array<double, 3>& background);
// When and where a report was made: {"time_utc": "2026-12-07 13:05 UTC", "device": ...,
// "driver": "llvmpipe Mesa 22.3.6, Vulkan 1.3.230"}, so that its figures can be dated and placed.
nlohmann::json report_made(const Context& ctx);
// The same as a sentence for a page: "Made 2026-12-07 13:05 UTC on <device> (<driver>)".
std::string report_made_text(const nlohmann::json& made);

// Above this background fraction a rendering counts as nearly empty.
inline constexpr double kNearlyEmptyFraction = 0.9;

// Renders, measures and writes the report into `dir` (created if missing; other files there are
// kept). Its files appear together when it is complete (host/io/atomic_file.h: an OutputBatch of
// its own, or the caller's), so a failed or interrupted report leaves nothing behind. Shows
// progress on a terminal. Throws std::runtime_error for unusable input (grids differ, an image
// too large for the device) or when a file cannot be written.
ReportSummary write_report(Context& ctx, const ReportInputs& inputs, const std::filesystem::path& dir);

// Checks what write_report() takes beyond its inputs for fields of `voxels` at `settings`' size,
// against the device and the memory budget (one sum where device memory is the host's): both
// fields and a residual map on the device, two residual maps on the host, the pictures. Throws
// MemoryBudgetExceeded or std::runtime_error naming the report; write_report() calls it first, a
// command before its solve so that a report that cannot fit fails before the work.
void check_report_memory(const Context& ctx, uint64_t voxels, const RenderSettings& settings);

// The names write_report() may write inside its directory (for FilePlan::output_directory).
std::vector<std::string> report_file_names();

// For a report written into `dir` when it already exists: schedules in `batch` the removal of the
// files there that a report of either kind writes (report_file_names(), series_report_file_names()
// for any number of fields) and that this report, which wrote `written`, did not. A directory
// reused for another run then holds one run's report: an earlier run's metrics.json or
// command.txt beside a new index.html would describe the wrong run. Other files are kept.
void remove_earlier_report_files(OutputBatch& batch, const std::filesystem::path& dir,
                                 const std::vector<std::string>& written);

}  // namespace tfm
