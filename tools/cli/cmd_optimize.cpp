// `tfmatch optimize`: fit a TF for a second field to a reference field and its TF.
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "render_options.h"
#include "solver_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/report/loss_plot.h"
#include "tfmatch/report/report.h"
#include "tfmatch/report/result_json.h"
#include "tfmatch/report/series_report.h"
#include "tfmatch/solvers/optimize.h"
#include "tfmatch/solvers/series_optimize.h"
#include "tfmatch/solvers/streamed_optimize.h"

namespace tfm::cli {
namespace {

struct OptimizeArgs {
  InputArgs in;                               // --ref, --ref-tf, --field, ranges, selectors, --tf-size
  std::vector<std::string> fields;            // every --field, expanded (in.field: the one of a single fit)
  bool shared_tf = false;                     // several fields: one TF for all
  std::string out, json;
  std::string solver = "normal-equations";
  double ridge = 0.0, smooth = 0.0;
  std::string factorization = "auto";
  std::map<std::string, std::string> extra;  // solver options (solver_options.h), checked by the solver
  std::string report;                         // report directory (renderings, metrics, index.html)
  std::vector<std::string> markers;           // drawn on the report's renderings
  std::string slice_point;                    // the report's slices go through it
  std::string histogram = "log";              // report TF plots: log or linear counts
  std::string stream = "auto";                // auto, on, off: read both fields slab by slab
  RenderSettings render;
  RenderChoices render_chosen;
  std::vector<std::string> picture_flags;     // the "Rendering" flags given, but --marker and --slice-point
};

// The render settings the report and an image-based solver use: the grid's defaults (a thin
// grid seen from above, its opacity scaled to the box's height), with their note when something
// renders, so that a scale given with --opacity-scale can be given scaled.
RenderSettings grid_render_settings(const OptimizeArgs& a, const std::array<uint64_t, 3>& dims,
                                    const std::array<double, 3>& spacing) {
  RenderSettings render = a.render;
  const std::string note = apply_grid_defaults(render, dims, spacing, a.render_chosen);
  if (!note.empty() && (!a.report.empty() || require_solver(a.solver).image_based())) print_note(note);
  return render;
}

// Picture flags shape the report's pictures, and those that an image-based solver or visibility
// weights fit; given for none of them, they would be dropped without a word (a usage error, as
// residual's picture flags without --image).
void check_picture_flags(const OptimizeArgs& a, const SolverSettings& settings) {
  if (!a.report.empty() || a.picture_flags.empty()) return;
  const bool histogram_only = a.picture_flags.size() == 1 && a.picture_flags.front() == "--histogram";
  const auto weights = settings.extra.find("weights");
  const bool fit_renders = require_solver(a.solver).image_based() ||
                           (weights != settings.extra.end() && weights->second == "visibility");
  if (fit_renders && std::find(a.picture_flags.begin(), a.picture_flags.end(), "--histogram") == a.picture_flags.end())
    return;
  std::vector<std::string> dropped;
  for (const std::string& f : a.picture_flags)
    if (!fit_renders || f == "--histogram") dropped.push_back(f);
  throw unused_picture_flags(dropped,
                             std::string("the report's pictures") +
                                 (histogram_only || fit_renders
                                      ? ""
                                      : " (and the renderings that diffdvr or --weights visibility fit)"),
                             "add --report DIR");
}

// The summary on stdout, or with -q the warnings alone on stderr: -q keeps warnings.
void print_result(const OptimizeResult& result) {
  if (!globals().quiet)
    result.print_summary(std::cout);
  else
    for (const std::string& w : result.warnings) print_warning(w);
}

// Both fields opened for a streamed run, or nothing when the run loads them whole: with
// --stream on; with auto when the solver streams, both files do and both fields as float32 take
// over a quarter of the memory budget (loaded whole, they are held on the host and the device).
struct Streams {
  std::unique_ptr<VolumeSlabReader> ref, field;
};
std::optional<Streams> open_streams(const OptimizeArgs& a) {
  // Under MPI the ranks split the slabs: streaming is how optimize runs there (docs/mpi.md).
  const bool distributed = globals().ranks->size() > 1;
  if (distributed && a.stream == "off")
    throw CLI::ValidationError("--stream", "under MPI (" + std::to_string(globals().ranks->size()) +
                                               " ranks) optimize reads both fields slab by slab: --stream on or auto");
  if (a.stream == "off") return std::nullopt;
  if (!solver_streams(a.solver)) {
    if (a.stream == "on" || distributed)
      throw CLI::ValidationError("--stream", "solver " + a.solver + " needs both fields in memory; the solvers that "
                                 "stream from disk are normal-equations and qp");
    return std::nullopt;
  }
  const VolumeOptions vo = a.in.volume.options({a.in.ref, a.in.field});
  Streams s;
  if (a.stream == "on" || distributed) {
    s = {open_volume_slabs(a.in.ref, vo), open_volume_slabs(a.in.field, vo)};
  } else {
    // auto: a file the slab readers refuse is left to the whole load, which says what is wrong.
    try {
      s = {open_volume_slabs(a.in.ref, vo), open_volume_slabs(a.in.field, vo)};
    } catch (const std::runtime_error&) {
      return std::nullopt;
    }
    if (!s.ref || !s.field) return std::nullopt;
    const uint64_t bytes = 2 * s.ref->grid().voxel_count() * sizeof(float);
    if (bytes <= memory_budget().bytes / 4) return std::nullopt;
    if (!globals().quiet)
      std::cerr << "tfmatch: streaming both fields from disk (" << format_bytes(bytes) << " as float32; memory budget "
                << format_bytes(memory_budget().bytes) << ", " << memory_budget().source << ")\n";
  }
  for (auto [reader, spec] : {std::pair{&s.ref, &a.in.ref}, std::pair{&s.field, &a.in.field}}) {
    if (*reader) continue;
    print_note(*spec + " cannot be read slab by slab (only raw, .dat, NetCDF and uncompressed raw-appended VTI "
               "can): loading it whole");
    *reader = slabs_in_memory(load_volume(*spec, vo));
  }
  return s;
}

// What a report records to be read and reproduced: its histogram scale, the command line, the
// version and the inputs (`tfmatch view --report` reopens them).
// The z-slices [first, end) in words: "z-slices 0–20", "z-slice 7", "no z-slice".
std::string slice_span(uint64_t first, uint64_t end) {
  if (first >= end) return "no z-slice";
  if (end - first == 1) return "z-slice " + std::to_string(first);
  return "z-slices " + std::to_string(first) + "–" + std::to_string(end - 1);
}

void add_provenance(ReportInputs& inputs, const OptimizeArgs& a) {
  inputs.histogram_log = a.histogram == "log";
  inputs.command_line = globals().command_line;
  inputs.version = version_line();
  inputs.inputs = input_args_json(a.in);
  inputs.inputs["solver"] = a.solver;
  inputs.inputs["solver_options"] = a.extra;
  inputs.inputs["ridge"] = a.ridge;
  inputs.inputs["smooth"] = a.smooth;
}

// `optimize` with both fields streamed from disk (streamed_optimize.h): the TF and voxel losses
// from all voxels, the report's pictures from box-filtered copies made during the same read.
int run_streamed(const OptimizeArgs& a, Context& ctx, Streams& streams, const SolverSettings& settings,
                 const JsonOutput& json, OutputBatch& outputs) {
  StreamedOptimizeRequest req;
  load_tf_and_ranges(a.in, req);
  req.ref = streams.ref.get();
  req.field = streams.field.get();
  req.solver = a.solver;
  req.settings = settings;
  req.ranks = globals().ranks;
  if (!a.report.empty()) req.preview_voxels = kDefaultPreviewVoxels;
  // Markers and the slice point name voxels of the whole grid: resolved there, then scaled.
  const std::vector<GridIndex> markers = resolve_markers(streams.ref->grid(), a.markers);
  const std::optional<GridIndex> slice_point = resolve_slice_point(streams.ref->grid(), a.slice_point);
  StreamedOptimizeResult s = run_optimize_streamed(ctx, req);
  // Every rank holds the same result; rank 0 reports and writes it (docs/mpi.md), with each
  // rank's peak memory (each fills its own entry; the maximum over ranks collects them).
  Ranks& job = *globals().ranks;
  const int ranks = job.size();
  std::vector<double> rank_peaks(size_t(ranks), 0.0);
  if (ranks > 1) {
    job.agree(nullptr);
    rank_peaks[size_t(job.rank())] = double(peak_resident_memory());
    job.max(rank_peaks);
  }
  if (job.rank() != 0) return 0;
  const OptimizeResult& result = s.result;
  const auto& d = streams.ref->grid().dims;
  const std::string how = std::string(s.streamed ? "streamed from disk" : "read slab by slab (a field loaded whole)") +
                          " in " + std::to_string(s.slabs) + (s.slabs == 1 ? " slab of " : " slabs of ") +
                          std::to_string(s.slab_slices) + " z-slices, " + std::to_string(s.passes) + (s.passes == 1 ? " pass" : " passes") +
                          " over the files" +
                          (ranks > 1 ? " (rank 0's share: " + slice_span(s.first_slice, s.end_slice) + " of " +
                                           std::to_string(d[2]) + ", " + std::to_string(ranks) + " MPI ranks)"
                                     : "");
  print_result(result);
  note_diverging_middle(a.in.ref_tf, req.ref_tf, req.ref_range.has_value(), result.ref_range, "--ref-range");
  if (!globals().quiet) std::cout << "  " << how << "\n";
  write_transfer_function(a.out, result.tf);
  nlohmann::json stream_json = {{"streamed", s.streamed},
                                {"passes", s.passes},
                                {"slabs", s.slabs},
                                {"slab_slices", s.slab_slices}};
  if (ranks > 1) {
    stream_json["mpi_ranks"] = ranks;
    stream_json["mpi_peak_rss_bytes"] = std::vector<uint64_t>(rank_peaks.begin(), rank_peaks.end());
  }
  nlohmann::json j = to_json(result);
  j["stream"] = stream_json;
  json.write(j);
  std::optional<ReportSummary> summary;
  if (!a.report.empty()) {
    set_progress_enabled(!globals().quiet);
    const Volume& ref = s.ref_preview;
    // The whole grid's shape decides, not the preview's.
    const RenderSettings render = grid_render_settings(a, streams.ref->grid().dims, streams.ref->grid().spacing);
    ReportInputs inputs{ref, s.field_preview, req.ref_tf, result, render};
    const uint64_t k = s.preview_factor;
    for (GridIndex m : markers) inputs.markers.push_back({m[0] / k, m[1] / k, m[2] / k});
    if (slice_point) inputs.slice_point = GridIndex{(*slice_point)[0] / k, (*slice_point)[1] / k, (*slice_point)[2] / k};
    inputs.title = "tfmatch: " + streams.field->grid().name + " matched to " + streams.ref->grid().name;
    inputs.notes.push_back(
        "Streamed run (" + how + "): the TF and the voxel RMSE come from all " + std::to_string(d[0]) + "×" +
        std::to_string(d[1]) + "×" + std::to_string(d[2]) + " voxels; the pictures, slices, histograms and image "
        "metrics are of copies box-filtered during the same read (each voxel the mean of the finite values of " +
        std::to_string(k) + "×" + std::to_string(k) + "×" + std::to_string(k) + " voxels: " +
        std::to_string(ref.dims[0]) + "×" + std::to_string(ref.dims[1]) + "×" + std::to_string(ref.dims[2]) +
        "). The voxel MAE is not measured in a streamed run.");
    stream_json["preview_factor"] = k;
    stream_json["preview_dims"] = ref.dims;
    stream_json["grid_dims"] = d;
    inputs.extra_metrics = {{"stream", stream_json}};
    add_provenance(inputs, a);
    summary = write_report(ctx, inputs, a.report);
  }
  outputs.commit();
  if (summary)
    for (const std::string& w : summary->warnings) print_warning(w);
  if (!globals().quiet) {
    std::cout << "  wrote " << a.out << (json.file().empty() ? "" : " and " + a.json) << "\n";
    if (summary)
      std::cout << "  images vs reference (box-filtered by " << s.preview_factor << "): reference TF "
                << summary->before.to_string() << "\n"
                << "                       optimized TF " << summary->after.to_string() << "\n"
                << "  report: " << summary->index.string() << "\n";
  }
  return 0;
}

// The TF file of field `index` of `count`: --out with "_<index>" before its extension
// (qvapor.json -> qvapor_007.json), zero-padded to the widest index (at least 3 digits).
std::string indexed_path(const std::string& out, size_t index, size_t count) {
  const std::filesystem::path p(out);
  std::string name = p.filename().string();
  const std::string paraview = ".paraview.json";
  const size_t ext = has_extension(name, paraview) ? name.size() - paraview.size() : name.rfind('.');
  const std::string digits = std::to_string(count - 1);
  std::string number = std::to_string(index);
  number.insert(0, std::max<size_t>(3, digits.size()) - number.size(), '0');
  name.insert(ext == std::string::npos ? name.size() : ext, "_" + number);
  return (p.parent_path() / name).string();
}

// `text` as one CSV field: in double quotes, a quote inside doubled (RFC 4180).
std::string csv_quoted(const std::string& text) {
  std::string out = "\"";
  for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// The series table beside --out: <stem>_series.csv.
std::string series_table_path(const std::string& out) {
  const std::filesystem::path p(out);
  std::string name = p.filename().string();
  const size_t dot = name.find('.');
  return (p.parent_path() / (name.substr(0, dot) + "_series.csv")).string();
}

// `optimize` with several fields (series_optimize.h): one TF per field (--out with an index per
// field) or one shared TF (--out), and the table of voxel RMSE before and after per field.
int run_series(const OptimizeArgs& a, const SolverSettings& settings, const JsonOutput& json) {
  const size_t count = a.fields.size();
  if (!a.markers.empty() || !a.slice_point.empty())
    throw CLI::ValidationError(a.markers.empty() ? "--slice-point" : "--marker",
                               "markers and slices belong to the report of one field");
  // Streamed: each field (and the reference again) read slab by slab; with auto when the solver
  // streams and the reference and one field as float32 exceed a quarter of the memory budget.
  bool stream = a.stream == "on";
  if (stream && !solver_streams(a.solver))
    throw CLI::ValidationError("--stream", "solver " + a.solver + " needs the fields in memory; the solvers that "
                               "stream from disk are normal-equations and qp");
  if (stream && !a.report.empty())
    throw CLI::ValidationError("--stream", "the series report renders every field whole: --stream off (or auto) "
                               "with --report");
  if (globals().ranks->size() > 1)
    throw CLI::ValidationError("--field", "several fields under MPI: not supported (each rank would fit them all)");
  if (a.shared_tf && !solver_fits_shared(a.solver))
    throw CLI::ValidationError("--shared-tf", "one TF for all fields is fitted from their summed system by "
                               "normal-equations or qp, not " + a.solver);
  FilePlan plan;
  plan.input_spec(a.in.ref, "--ref").input_spec(a.in.ref_tf, "--ref-tf");
  for (size_t i = 0; i < count; ++i) plan.input_spec(a.fields[i], "--field " + std::to_string(i + 1));
  std::vector<std::string> tf_files;
  if (a.shared_tf) {
    tf_files.push_back(a.out);
  } else {
    for (size_t i = 0; i < count; ++i) tf_files.push_back(indexed_path(a.out, i, count));
  }
  for (const std::string& f : tf_files) plan.output(f, "--out");
  const std::string table = series_table_path(a.out);
  plan.output(table, "--out (series table)").output(json.file(), "--json");
  plan.output_directory(a.report, "--report", series_report_file_names(count)).check();
  if (!a.report.empty()) validate(a.render);  // fail before the fits, not after

  StartingContext starting;
  OutputBatch outputs;
  std::vector<std::string> inputs = a.fields;
  inputs.push_back(a.in.ref);
  const VolumeOptions vo = a.in.volume.options(inputs);
  if (a.stream == "auto" && solver_streams(a.solver) && a.report.empty()) {
    const std::unique_ptr<VolumeSlabReader> probe = open_volume_slabs_or_load(a.in.ref, vo);
    const uint64_t bytes = 2 * probe->grid().voxel_count() * sizeof(float);
    stream = probe->streams() && bytes > memory_budget().bytes / 4;
    if (stream && !globals().quiet)
      std::cerr << "tfmatch: streaming the reference and each field from disk (" << format_bytes(bytes)
                << " as float32 per pair; memory budget " << format_bytes(memory_budget().bytes) << ", "
                << memory_budget().source << ")\n";
  }
  // The reference in memory, or its grid alone when streamed (read again for each field).
  const Volume ref = stream ? open_volume_slabs_or_load(a.in.ref, vo)->grid() : load_volume(a.in.ref, vo);
  SeriesRequest req;
  load_tf_and_ranges(a.in, req);
  req.ref = stream ? nullptr : &ref;
  req.solver = a.solver;
  req.settings = settings;
  const RenderSettings render = grid_render_settings(a, ref.dims, ref.spacing);  // image-based solvers render too
  req.settings.render = render;
  req.shared_tf = a.shared_tf;
  req.field_count = count;
  Progress progress("fields", count * (a.shared_tf && a.in.field_range.empty() ? 2 : 1));  // a shared fit reads the fields twice for their range
  size_t loads = 0;
  if (stream) {
    req.open_ref_slabs = [&] { return open_volume_slabs_or_load(a.in.ref, vo); };
    req.open_field_slabs = [&](size_t i) {
      std::unique_ptr<VolumeSlabReader> r = open_volume_slabs_or_load(a.fields[i], vo);
      progress.update(++loads);
      return r;
    };
  } else {
    req.load_field = [&](size_t i) {
      Volume v = load_volume(a.fields[i], vo);
      progress.update(++loads);
      return v;
    };
  }
  auto ctx = starting.get();
  if (!a.report.empty()) check_render_size(*ctx, render);
  const SeriesResult s = run_optimize_series(*ctx, req);
  progress.finish();
  std::optional<SeriesReportSummary> summary;
  if (!a.report.empty()) {
    set_progress_enabled(!globals().quiet);
    SeriesReportInputs inputs{ref, req.ref_tf, s, render};
    // Each field as loaded: its name carries the time or member --time/--member chose.
    for (const SeriesFieldResult& f : s.fields)
      inputs.labels.push_back(std::filesystem::path(f.name).filename().string());
    inputs.load_field = [&](size_t i) { return load_volume(a.fields[i], vo); };
    inputs.title = "tfmatch: " + std::to_string(count) + " fields matched to " + ref.name;
    inputs.histogram_log = a.histogram == "log";
    inputs.command_line = globals().command_line;
    inputs.version = version_line();
    summary = write_series_report(*ctx, inputs, a.report);
  }

  for (size_t i = 0; i < tf_files.size(); ++i) write_transfer_function(tf_files[i], a.shared_tf ? s.tf : s.fields[i].tf);
  std::ostringstream csv;
  csv << "index,field,tf_file,field_lo,field_hi,voxels,voxel_rmse_before,voxel_rmse_after\n";
  nlohmann::json rows = nlohmann::json::array();
  for (size_t i = 0; i < count; ++i) {
    const SeriesFieldResult& f = s.fields[i];
    const std::string& tf_file = tf_files[a.shared_tf ? 0 : i];
    csv << i << "," << csv_quoted(f.name) << "," << csv_quoted(tf_file) << "," << std::setprecision(9)
        << f.field_range.lo << "," << f.field_range.hi << "," << f.after.voxels << "," << f.before.rmse() << "," << f.after.rmse() << "\n";
    rows.push_back({{"index", i},
                    {"field", a.fields[i]},
                    {"name", f.name},
                    {"tf_file", tf_file},
                    {"field_range", {f.field_range.lo, f.field_range.hi}},
                    {"voxels", f.after.voxels},
                    {"voxel_rmse_before", f.before.rmse()},
                    {"voxel_rmse_after", f.after.rmse()},
                    {"warnings", f.warnings}});
  }
  write_file_atomically(table, csv.str());
  nlohmann::json j = {{"solver", s.solver},
                      {"device", s.device},
                      {"shared_tf", s.shared_tf},
                      {"ref_range", {s.ref_range.lo, s.ref_range.hi}},
                      {"fields", rows},
                      {"voxel_rmse_before", s.before.rmse()},
                      {"voxel_rmse_after", s.after.rmse()},
                      {"series_table", table},
                      {"warnings", s.warnings}};
  if (s.shared_tf) j["details"] = to_json(s.details);
  json.write(j);
  outputs.commit();
  if (!globals().quiet) {
    std::cout << "tfmatch optimize: " << count << " fields against " << ref.name << " on " << s.device << ", solver "
              << s.solver << (s.shared_tf ? ", one shared TF" : ", one TF per field") << "\n"
              << "  field                                     voxel RMSE: reference TF -> optimized\n";
    for (size_t i = 0; i < count; ++i)
      std::cout << "  " << std::left << std::setw(40) << std::filesystem::path(s.fields[i].name).filename().string()
                << std::right << std::fixed << std::setprecision(5) << std::setw(10) << s.fields[i].before.rmse()
                << " -> " << s.fields[i].after.rmse() << std::defaultfloat << "\n";
    for (const std::string& w : s.warnings) std::cout << "  warning: " << w << "\n";
    for (const SeriesFieldResult& f : s.fields)
      for (const std::string& w : f.warnings) std::cout << "  warning (" << f.name << "): " << w << "\n";
    std::cout << "  wrote " << (a.shared_tf ? a.out : tf_files.front() + " .. " + tf_files.back()) << ", " << table
              << (json.file().empty() ? "" : " and " + a.json) << "\n";
    if (summary) std::cout << "  report: " << summary->index.string() << "\n";
  } else {  // -q keeps warnings
    for (const std::string& w : s.warnings) print_warning(w);
    for (const SeriesFieldResult& f : s.fields)
      for (const std::string& w : f.warnings) print_warning(f.name + ": " + w);
  }
  return 0;
}

int run(const OptimizeArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  SolverSettings settings;
  settings.render = a.render;  // image-based solvers render as the report does
  settings.solve.ridge = a.ridge;
  settings.solve.smooth = a.smooth;
  settings.extra = a.extra;
  settings.solve.factorization = a.factorization == "ldlt" ? Factorization::LDLT : Factorization::Auto;
  // Bad or misapplied solver flags fail before loading, as usage errors.
  check_usage([&] { parse_solver_args(require_solver(a.solver), settings); });
  check_picture_flags(a, settings);
  if (a.fields.size() > 1) return run_series(a, settings, json);
  if (a.shared_tf) throw CLI::ValidationError("--shared-tf", "one TF shared by several fields: give several --field");
  // Every file checked before any work: no output replaces an input or another output. Under
  // MPI every rank reads and rank 0 alone writes (docs/mpi.md): a node where the output folder is
  // read-only or missing stopped the job, though it would write nothing.
  FilePlan plan;
  plan.input_spec(a.in.ref, "--ref").input_spec(a.in.field, "--field").input_spec(a.in.ref_tf, "--ref-tf");
  if (globals().ranks->rank() == 0)
    plan.output(a.out, "--out").output(json.file(), "--json").output_directory(a.report, "--report", report_file_names());
  plan.check();
  if (!a.report.empty()) validate(a.render);  // fail before the solve, not after
  if (a.report.empty() && !a.markers.empty())
    throw CLI::ValidationError("--marker", "markers are drawn on the report's renderings: add --report DIR");
  if (a.report.empty() && !a.slice_point.empty())
    throw CLI::ValidationError("--slice-point", "slices are part of the report: add --report DIR");
  StartingContext starting;  // the device starts while the fields are read
  OutputBatch outputs;  // nothing appears unless every output is complete
  if (std::optional<Streams> streams = open_streams(a)) {
    auto ctx = starting.get();
    if (!a.report.empty()) check_render_size(*ctx, a.render);
    return run_streamed(a, *ctx, *streams, settings, json, outputs);
  }
  LoadedInputs loaded;
  try {
    load_inputs(a.in, loaded);
  } catch (const MemoryBudgetExceeded& e) {
    if (solver_streams(a.solver)) throw;
    throw MemoryBudgetExceeded(std::string(e.what()) + " (normal-equations and qp read volumes larger than memory "
                               "slab by slab from disk: --solver normal-equations --stream on)");
  }
  auto ctx = starting.get();
  const Volume& ref = loaded.ref;
  // Image-based solvers render what the report shows: both take the grid's defaults.
  const RenderSettings render = grid_render_settings(a, ref.dims, ref.spacing);
  settings.render = render;
  // The report's needs on top of the loaded fields, before the solve rather than after it.
  if (!a.report.empty()) check_report_memory(*ctx, ref.voxel_count(), render);
  const std::vector<GridIndex> markers = resolve_markers(ref, a.markers);
  const std::optional<GridIndex> slice_point = resolve_slice_point(ref, a.slice_point);
  const Volume& field = loaded.field;
  OptimizeRequest& req = loaded.request;
  req.solver = a.solver;
  req.settings = settings;
  req.voxel_mae = !a.json.empty() || !a.report.empty();  // both show the mean absolute error
  OptimizeResult result = run_optimize(*ctx, req);
  print_result(result);
  note_diverging_middle(a.in.ref_tf, req.ref_tf, req.ref_range.has_value(), result.ref_range, "--ref-range");
  write_transfer_function(a.out, result.tf);
  json.write(to_json(result));
  std::optional<ReportSummary> summary;
  if (!a.report.empty()) {
    set_progress_enabled(!globals().quiet);
    ReportInputs inputs{ref, field, req.ref_tf, result, render};
    inputs.extra_figures = solver_report_figures(result, render.width);  // diffdvr: loss curve
    inputs.title = "tfmatch: " + field.name + " matched to " + ref.name;
    inputs.markers = markers;
    inputs.slice_point = slice_point;
    add_provenance(inputs, a);
    summary = write_report(*ctx, inputs, a.report);
  }
  outputs.commit();
  if (summary)
    for (const std::string& w : summary->warnings) print_warning(w);
  if (!globals().quiet) {
    std::cout << "  wrote " << a.out << (json.file().empty() ? "" : " and " + a.json) << "\n";
    if (summary)
      std::cout << "  images vs reference: reference TF " << summary->before.to_string() << "\n"
                << "                       optimized TF " << summary->after.to_string() << "\n"
                << "  report: " << summary->index.string() << "\n";
  }
  return 0;
}

CommandRegistration reg(10, [](CLI::App& app) {
  auto args = std::make_shared<OptimizeArgs>();
  auto* sub = app.add_subcommand("optimize", "Optimize a transfer function for FIELD to match REF rendered with REF-TF");
  add_input_options(sub, args->in, /*required=*/true);
  // --field takes several fields here: one TF each, or one shared TF.
  sub->remove_option(sub->get_option("--field"));
  sub->add_option("--field", args->fields, "Field whose transfer function is optimized; several (repeat --field, "
                  "FILE:VAR,time=A..B or member=A..B, or a quoted pattern 'dir/*.vti', in natural order): one TF "
                  "each, written to --out with an index (tf_000.json, ...), or one for all with --shared-tf; a table "
                  "<out>_series.csv")
      ->required();
  sub->add_flag("--shared-tf", args->shared_tf, "Several fields: fit one TF to all of them together (normal-equations, "
                "qp), written to --out");
  sub->add_option("--out", args->out, "Optimized transfer function (.json, .xml or .paraview.json)")->required()
      ->check(output_format(transfer_function_format()));
  sub->add_option("--solver", args->solver, "Solver: " + solver_name_list() + " (described below)")
      ->capture_default_str();
  sub->add_option("--ridge", args->ridge, "Tikhonov weight, relative to the mean diagonal of M")
      ->check(non_negative());
  sub->add_option("--smooth", args->smooth, "First-difference smoothness weight, relative to the mean diagonal of M, at most 1e9 "
                  "(diffdvr: weight of (N-1) sum of squared TF differences, added to the mean image loss, at most 1e9)")
      ->check(non_negative());
  sub->add_option("--factorization", args->factorization, "normal-equations: auto (LDL^T deciding the rank entry by "
                  "entry: the minimum-norm solution when M is singular) or ldlt (no rank decision)")
      ->check(CLI::IsMember({"auto", "ldlt"}))->capture_default_str();
  add_json_option(sub, args->json, "the summary");
  add_solver_options(sub, args->extra);
  sub->add_option("--report", args->report, "Write a report into this directory: renderings before/after, residual "
                  "maps, TF plots, metrics.json, index.html");
  add_render_options(sub, args->render);
  add_marker_option(sub, args->markers);
  add_slice_point_option(sub, args->slice_point);
  add_histogram_option(sub, args->histogram);
  sub->add_option("--stream", args->stream, "Read both fields from disk slab by slab, so memory does not grow with "
                  "the voxel count (normal-equations and qp; raw, .dat, NetCDF, uncompressed VTI): on, off, or auto "
                  "(when both fields as float32 exceed a quarter of --max-memory / the available memory). The report "
                  "then shows box-filtered copies")
      ->check(CLI::IsMember({"auto", "on", "off"}))->capture_default_str();
  sub->footer(solver_descriptions());
  sub->callback([args, sub] {
    args->render_chosen = render_choices(*sub);
    args->picture_flags = given_picture_flags(*sub, {}, {"--marker", "--slice-point"});  // own messages
    args->fields = expand_field_specs(args->fields, "--field");
    args->in.field = args->fields.front();
    exit_code() = run(*args);
  });
});

}  // namespace
}  // namespace tfm::cli
