// `tfmatch correlate`: the correlation field of an ensemble for a reference point (or the
// difference of two points' fields), written as a field that `optimize`, `render` and `residual`
// read like any other.
#include <algorithm>
#include <array>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <span>
#include <string>
#include <vector>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "render_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/ensemble_io.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/kernels/correlation_field.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/ranks.h"

namespace tfm::cli {
namespace {

struct CorrelateArgs {
  std::string ensemble;
  std::vector<std::string> members;
  std::string point, point2, measure = "pearson", out, json;
  uint32_t bins = 16, k = 3;
  bool absolute = false;
  std::string member_dim;
  std::string stream = "auto";  // read the members slab by slab (docs/ensembles.md, docs/mpi.md)
  uint64_t slab_slices = 0;     // z-slices per slab (0: from the memory budget)
  VolumeFlags volume_flags;  // raw layout, --var, --time
};

// .vti, .raw, or ParaView's parallel image data: a .pvti and a .vti piece per MPI rank.
const OutputFormat& correlation_output_format() {
  static const OutputFormat f{{".vti", ".raw", ".pvti"},
                              "field (.vti VTK ImageData, .raw float32, or .pvti ParaView parallel image data)"};
  return f;
}

std::string field_name(const CorrelateArgs& a) {
  std::string n = a.measure + (a.point2.empty() ? "" : "_difference");
  return a.absolute ? "abs_" + n : n;
}

// What the summary says of a field's values.
struct FieldStats {
  uint64_t voxels = 0, nan = 0;
  double lo = INFINITY, hi = -INFINITY;
  void add(std::span<const float> values) {
    voxels += values.size();
    for (float v : values) {
      if (std::isnan(v)) ++nan;
      else lo = std::min(lo, double(v)), hi = std::max(hi, double(v));
    }
  }
};

// The JSON summary of a field written to a.out.
void write_field_summary(const CorrelateArgs& a, const JsonOutput& json, const FieldStats& stats, const Volume& grid,
                         const std::string& source, uint32_t members, const CorrelationParams& params,
                         const GridIndex& p1, const std::optional<GridIndex>& p2, const std::string& device,
                         double load_s, double compute_s, const nlohmann::json& extra) {
  const uint64_t nan = stats.nan, voxels = stats.voxels;
  const double lo = stats.lo, hi = stats.hi;
  nlohmann::json j = {{"ensemble", source},
                      {"members", members},
                      {"grid", grid.dims},
                      {"measure", correlation_measure_name(params.measure)},
                      {"strategy", CorrelationKernel::strategy(params, members)},
                      {"point", p1},
                      {"point_description", describe_grid_point(grid, p1)},
                      {"absolute", a.absolute},
                      {"nan_voxels", nan},
                      {"min", nan == voxels ? nlohmann::json() : nlohmann::json(lo)},
                      {"max", nan == voxels ? nlohmann::json() : nlohmann::json(hi)},
                      {"out", a.out},
                      {"device", device},
                      {"seconds", {{"load", load_s}, {"compute", compute_s}}}};
  if (params.measure == CorrelationMeasure::MiBinned) j["bins"] = params.bins;
  if (params.measure == CorrelationMeasure::MiKraskov || params.measure == CorrelationMeasure::MiCoefficient) j["k"] = params.k;
  if (p2) j["point2"] = *p2, j["point2_description"] = describe_grid_point(grid, *p2);
  for (const auto& [key, value] : extra.items()) j[key] = value;
  json.write(j);
}

// The printed summary of a field written to a.out.
void print_field_summary(const CorrelateArgs& a, const FieldStats& stats, const Volume& grid, const std::string& source,
                         uint32_t members, const CorrelationParams& params, const GridIndex& p1,
                         const std::optional<GridIndex>& p2, const std::string& device, double compute_s) {
  const bool vti = has_extension(a.out, ".vti"), pvti = has_extension(a.out, ".pvti");
  const uint64_t nan = stats.nan, voxels = stats.voxels;
  const double lo = stats.lo, hi = stats.hi;
  const auto& d = grid.dims;
  std::cout << "ensemble " << source << ": " << members << " members on " << d[0] << "x" << d[1] << "x" << d[2]
            << "\n  reference point " << describe_grid_point(grid, p1) << "\n";
  if (p2) std::cout << "  minus point     " << describe_grid_point(grid, *p2) << "\n";
  std::cout << "  " << correlation_measure_name(params.measure) << " (" << CorrelationKernel::strategy(params, members)
            << ") on " << device << " in " << compute_s << " s";
  if (nan < voxels) std::cout << ": range [" << lo << ", " << hi << "]";
  if (nan > 0) std::cout << ", " << nan << " voxels NaN (no data in some member)";
  std::cout << "\n  wrote " << a.out
            << (pvti  ? " (ParaView parallel image data: one .vti piece per rank, the source's origin and spacing)"
                : vti ? " (VTK ImageData, the source's origin and spacing)"
                      : " (float32 little-endian, x fastest)")
            << "\n";
}

// The JSON summary and the printed summary of a field written to a.out (rank 0's); `extra` joins
// the JSON. Then the staged outputs are committed, on every rank of `ranks` once the summary is
// written: a rank's .pvti piece never replaces an earlier run's unless every file of this one
// does. Collective (ranks.h).
void summarize_field(const CorrelateArgs& a, const JsonOutput& json, OutputBatch& outputs, const FieldStats& stats,
                     const Volume& grid, const std::string& source, uint32_t members, const CorrelationParams& params,
                     const GridIndex& p1, const std::optional<GridIndex>& p2, const std::string& device, double load_s,
                     double compute_s, const nlohmann::json& extra, Ranks& ranks = single_rank()) {
  std::exception_ptr failed;
  if (ranks.rank() == 0) {
    try {
      write_field_summary(a, json, stats, grid, source, members, params, p1, p2, device, load_s, compute_s, extra);
    } catch (...) {
      failed = std::current_exception();
    }
  }
  ranks.agree(failed);
  outputs.commit();
  if (ranks.rank() == 0 && !globals().quiet)
    print_field_summary(a, stats, grid, source, members, params, p1, p2, device, compute_s);
}

// The field from members read slab by slab (correlation_field_streamed): each rank of an MPI job
// its own z-slices (docs/mpi.md), gathered on rank 0, which writes it.
// The pieces of a .pvti: <dir>/<stem>/<stem>_<rank>.vti beside <dir>/<stem>.pvti.
std::string piece_source(const std::filesystem::path& out, int rank) {
  const std::string stem = out.stem().string();
  return stem + "/" + stem + "_" + std::to_string(rank) + ".vti";
}

// Pieces an earlier run with more ranks left (<stem>_<N>.vti for N >= `pieces`), which no .pvti
// lists any more: removed once the new files are in place. Other files in the folder are kept.
void remove_stale_pieces(const std::filesystem::path& out, int pieces) {
  namespace fs = std::filesystem;
  const std::string prefix = out.stem().string() + "_";
  std::vector<fs::path> stale;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(out.parent_path() / out.stem(), ec)) {
    const std::string name = entry.path().filename().string();
    if (!name.starts_with(prefix) || !name.ends_with(".vti")) continue;
    const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - 4);
    const bool number = std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; });
    if (digits.empty() || digits.size() > 9 || !number) continue;
    const int rank = std::stoi(digits);
    if (rank >= pieces && std::to_string(rank) == digits) stale.push_back(entry.path());
  }
  for (const auto& path : stale) fs::remove(path, ec);
}

// ParaView's parallel image data (write_pvti): every rank writes its piece, z-slices [first, end)
// and the next rank's first slice (`values` holds them: slices [first, computed_end)), then rank 0
// the .pvti naming every rank's piece; returns how many pieces it names. Collective (ranks.h). The
// files are staged in `outputs`, committed with the summary (summarize_field); a failure anywhere
// leaves none of them (and rank 0's batch removes the pieces' directory if it made it).
int write_pieces(const CorrelateArgs& a, std::span<const float> values, const Volume& grid, const std::string& name,
                 Ranks& ranks, OutputBatch& outputs, uint64_t first, uint64_t end, uint64_t computed_end) {
  namespace fs = std::filesystem;
  const fs::path out = a.out;
  const fs::path dir = out.parent_path() / out.stem();
  std::exception_ptr failed;
  int pieces = 0;  // ranks with slices: a job of more ranks than z-slices has fewer pieces
  for (int r = 0; r < ranks.size(); ++r) {
    const auto [f, e] = rank_slices(grid.dims[2], r, ranks.size());
    pieces += f < e ? 1 : 0;
  }
  if (ranks.rank() == 0) {
    try {
      // Every rank writes into it, so it is made here rather than staged by the batch, which
      // removes it again (once empty) if the run fails, after the summary as before it.
      if (!fs::exists(dir)) {
        fs::create_directories(dir);
        outputs.made_directory(dir);
      }
    } catch (...) {
      failed = std::current_exception();
    }
  }
  ranks.agree(failed);
  try {
    if (first < end) {
      Volume piece = empty_like(grid);
      piece.dims[2] = computed_end - first;
      piece.values.assign(values.begin(), values.end());
      VtiWriteOptions options;
      options.extent_offset = {0, 0, first};
      write_vti(out.parent_path() / piece_source(out, ranks.rank()), piece, name, options);
    }
  } catch (...) {
    failed = std::current_exception();
  }
  ranks.agree(failed);
  if (ranks.rank() == 0) {
    try {
      std::vector<PvtiPiece> pieces;
      const uint64_t nz = grid.dims[2];
      for (int r = 0; r < ranks.size(); ++r) {
        const auto [f, e] = rank_slices(nz, r, ranks.size());
        if (f < e) pieces.push_back({f, std::min(e, nz - 1), piece_source(out, r)});
      }
      write_pvti(out, grid, name, pieces);
    } catch (...) {
      failed = std::current_exception();
    }
  }
  ranks.agree(failed);
  return pieces;
}

// Writes the whole field (VTI, raw, or a one-piece .pvti) and summarizes it.
void write_field(const CorrelateArgs& a, const JsonOutput& json, OutputBatch& outputs, const Volume& field,
                 const Volume& grid, const std::string& source, uint32_t members, const CorrelationParams& params,
                 const GridIndex& p1, const std::optional<GridIndex>& p2, const std::string& device, double load_s,
                 double compute_s, const nlohmann::json& extra) {
  const bool pvti = has_extension(a.out, ".pvti");
  if (pvti) {
    write_pieces(a, field.values, grid, field.name, single_rank(), outputs, 0, grid.dims[2], grid.dims[2]);
  } else if (has_extension(a.out, ".vti")) {
    write_vti(a.out, field, field.name);
  } else {
    write_raw_float32(a.out, field);
  }
  FieldStats stats;
  stats.add(field.values);
  summarize_field(a, json, outputs, stats, grid, source, members, params, p1, p2, device, load_s, compute_s, extra);
  if (pvti) remove_stale_pieces(a.out, 1);
}

int run_streamed(const CorrelateArgs& a, const CorrelationParams& params, const JsonOutput& json, OutputBatch& outputs,
                 StartingContext& starting, EnsembleSlabs& slabs, std::chrono::steady_clock::time_point t0) {
  const Volume& grid = slabs.grid();
  const std::string& source = slabs.name;
  const uint32_t members = static_cast<uint32_t>(slabs.members.size());
  if (members < 3)
    throw std::runtime_error(source + ": " + std::to_string(members) +
                             " member(s); a correlation over members needs at least 3");
  try {
    validate_correlation_params(params, members);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(source + ": " + e.what());
  }
  CorrelationRequest request;
  request.params = params;
  request.absolute = a.absolute;
  const GridIndex p1 = resolve_point(grid, a.point, "--point");
  request.point = linear_index(grid, p1);
  std::optional<GridIndex> p2;
  if (!a.point2.empty()) {
    p2 = resolve_point(grid, a.point2, "--point2");
    request.point2 = linear_index(grid, *p2);
  }
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  auto ctx = starting.get();
  Ranks& ranks = *globals().ranks;
  require_same_grid_on_every_rank(ranks, grid, source, members);
  const auto [first, end] = rank_slices(grid.dims[2], ranks.rank(), ranks.size());
  const uint64_t slice = grid.dims[0] * grid.dims[1];
  // A slab of every member within a quarter of what the budget leaves (under MPI the smallest
  // rank's, so that the ranks move in step), measured once the kernel has run: what the driver's
  // compiler keeps counts too (lavapipe, validation layer on, cold shader cache: measured before
  // it, the peak passed a budget of 240 MiB by 14 MB).
  CorrelationKernel kernel(*ctx);
  kernel.prepare(params, members);
  // What this rank holds beside its slabs at its peak: the field it computes, and what writing it
  // takes (a .vti's compressed payload is a copy, twice its size, as the write checks); rank 0 of
  // a job writing one .vti or raw file also the gathered whole. Checked here, before the work,
  // not at the gather or the write after the whole computation, and off the slabs' share.
  const bool pvti = has_extension(a.out, ".pvti"), vti = has_extension(a.out, ".vti");
  const uint64_t part_bytes = (end - first + 1) * slice * sizeof(float), whole = grid.voxel_count() * sizeof(float);
  const bool gathered = ranks.size() > 1 && !pvti;
  uint64_t peak = part_bytes;
  std::string peak_what;
  if (pvti) {
    peak = 3 * part_bytes;
    peak_what = a.out + ": " + (ranks.size() > 1 ? "this rank's piece" : "the field") + " of " +
                std::to_string(end - first) + " z-slices and its compressed copy as it is written";
  } else if (ranks.rank() == 0) {
    peak = std::max(whole + (gathered ? part_bytes : 0), whole + (vti ? 2 * whole : 0));
    peak_what = gathered ? a.out + ": rank 0 gathers the whole " + std::to_string(grid.dims[0]) + "x" +
                               std::to_string(grid.dims[1]) + "x" + std::to_string(grid.dims[2]) +
                               " field to write it (a .pvti output keeps each rank's piece on its rank)"
                         : a.out + (vti ? ": the field and its compressed copy as it is written" : ": the field");
  }
  std::exception_ptr refused;
  try {
    if (gathered && ranks.rank() == 0 && grid.voxel_count() > uint64_t(INT32_MAX))  // MPI_Gatherv counts in int
      throw CLI::ValidationError("--out", a.out + ": a field gathered on rank 0 holds at most 2^31 - 1 voxels, this one " +
                                              std::to_string(grid.voxel_count()) + ": write .pvti pieces instead");
    if (!peak_what.empty()) check_memory(peak, peak_what);
  } catch (...) {
    if (ranks.size() == 1) throw;
    refused = std::current_exception();
  }
  const uint64_t held = resident_memory() + peak, budget = memory_budget().bytes;
  uint64_t slab = a.slab_slices ? a.slab_slices
                                : correlation_slab_slices(members, slice, (budget > held ? budget - held : 0) / 4);
  if (ranks.size() > 1) {
    // Every rank has its device (a rank that failed to start stops them all here), and room for
    // its field and its write.
    ranks.agree(refused);
    std::array<double, 1> smallest{double(slab)};
    ranks.min(smallest);
    slab = uint64_t(smallest[0]);
  }
  // A .pvti piece also holds the next piece's first slice: neighbouring pieces share a slice.
  const uint64_t computed_end = pvti && first < end ? std::min(end + 1, grid.dims[2]) : end;
  // The job's progress on rank 0: after each slab the ranks add up their voxels done; a rank with
  // fewer slabs meets the others as often (steps: the most slabs any rank has).
  uint64_t steps = 0, my_steps = 0, my_done = 0, job_voxels = 0;
  for (int r = 0; r < ranks.size(); ++r) {
    const auto [f, e] = rank_slices(grid.dims[2], r, ranks.size());
    const uint64_t n = pvti && f < e ? std::min(e + 1, grid.dims[2]) - f : e - f;
    steps = std::max(steps, (n + slab - 1) / slab);
    job_voxels += n * slice;
  }
  slab = std::min(std::max<uint64_t>(1, computed_end - first), slab);  // the same slabs, as said in the summary
  const uint64_t passes = p2 ? 2 : 1;
  Progress progress(std::string(correlation_measure_name(params.measure)) + " over " + std::to_string(members) +
                        " members, slab by slab" + (ranks.size() > 1 ? ", " + std::to_string(ranks.size()) + " ranks" : ""),
                    job_voxels * passes);
  auto meet = [&] {
    ++my_steps;
    ranks.agree(nullptr);
    std::array<uint64_t, 1> done{my_done * passes};
    ranks.sum(std::span<uint64_t>(done));
    if (ranks.rank() == 0) progress.update(done[0]);
  };
  std::vector<VolumeSlabReader*> readers;
  for (const auto& m : slabs.members) readers.push_back(m.get());
  const auto t1 = std::chrono::steady_clock::now();
  std::vector<float> part;
  std::exception_ptr failed;
  try {
    CorrelationProgress within_slab;
    if (ranks.size() == 1) within_slab = [&](uint64_t done, uint64_t) { progress.update(done); };
    std::function<void(uint64_t)> after_slab;
    if (ranks.size() > 1)
      after_slab = [&](uint64_t done) {
        my_done = done;
        meet();
      };
    part = correlation_field_streamed(kernel, readers, request, slab, first, computed_end, within_slab, after_slab);
    while (my_steps < steps) meet();  // the others' remaining slabs
  } catch (const RankFailure&) {
    throw;  // another rank failed: agreed already
  } catch (const std::invalid_argument& e) {  // a reference point that cannot be one
    failed = std::make_exception_ptr(std::runtime_error(source + ": " + e.what()));
  } catch (...) {
    failed = std::current_exception();
  }
  ranks.agree(failed);  // every rank computed its share, or every rank stops here
  nlohmann::json stream = {{"streamed", slabs.streams()},
                           {"slab_slices", slab},
                           {"slabs", (computed_end - first + slab - 1) / slab}};
  if (ranks.size() > 1) stream["mpi_ranks"] = ranks.size();
  if (pvti) {
    // Each rank writes its piece; the summary's numbers are reduced over the ranks' own slices.
    const int pieces = write_pieces(a, part, grid, field_name(a), ranks, outputs, first, end, computed_end);
    FieldStats stats;
    stats.add(std::span<const float>(part.data(), (end - first) * slice));
    std::array<uint64_t, 2> counts{stats.voxels, stats.nan};
    std::array<double, 1> lo{stats.lo}, hi{stats.hi};
    ranks.agree(nullptr);
    ranks.sum(std::span<uint64_t>(counts));
    ranks.min(lo);
    ranks.max(hi);
    stats = {counts[0], counts[1], lo[0], hi[0]};
    const double compute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    stream["pieces"] = pieces;
    summarize_field(a, json, outputs, stats, grid, source, members, params, p1, p2, ctx->device_name(), load_s,
                    compute_s, {{"stream", stream}}, ranks);
    if (ranks.rank() == 0) remove_stale_pieces(a.out, pieces);
    return 0;
  }
  // One rank keeps its field: a gather would hold it twice.
  std::vector<float> all = ranks.size() == 1 ? std::move(part) : ranks.gather(part);
  std::vector<float>().swap(part);  // rank 0 writes the gathered field without its part beside it
  const double compute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  if (ranks.rank() != 0) return 0;
  Volume field = empty_like(grid);
  field.name = field_name(a);
  field.values = std::move(all);
  write_field(a, json, outputs, field, grid, source, members, params, p1, p2, ctx->device_name(), load_s, compute_s,
              {{"stream", stream}});
  return 0;
}

int run(const CorrelateArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  set_progress_enabled(!globals().quiet);
  if (a.ensemble.empty() == a.members.empty())
    throw CLI::ValidationError("correlate", "give the ensemble either as --ensemble FILE[:VAR] or as --members FILE...");
  CorrelationParams params;
  try {
    params.measure = parse_correlation_measure(a.measure);
  } catch (const std::invalid_argument& e) {
    throw CLI::ValidationError("--measure", e.what());
  }
  params.bins = a.bins;
  params.k = a.k;

  const std::vector<std::string> member_files = a.members.empty() ? std::vector<std::string>{}
                                                                     : expand_member_patterns(a.members);
  FilePlan files;
  files.input_spec(a.ensemble, "--ensemble");
  for (const std::string& m : member_files) files.input_spec(m, "--members");
  files.output(a.out, "--out").output(json.file(), "--json");
  if (has_extension(a.out, ".pvti")) {
    // The pieces' folder beside it, checked with the rest before any work (a file of that name
    // failed the run once the field was computed).
    std::vector<std::string> pieces;
    for (int r = 0; r < globals().ranks->size(); ++r)
      pieces.push_back(std::filesystem::path(piece_source(a.out, r)).filename().string());
    const std::filesystem::path out = a.out;
    files.output_directory(out.parent_path() / out.stem(), "--out (its pieces' folder)", pieces);
  }
  files.check();
  OutputBatch outputs;

  VolumeOptions vo = a.volume_flags.options(a.ensemble.empty() ? member_files : std::vector<std::string>{a.ensemble});
  vo.member_dim = a.member_dim;
  const bool distributed = globals().ranks->size() > 1;
  if (distributed && a.stream == "off")
    throw CLI::ValidationError("--stream", "under MPI (" + std::to_string(globals().ranks->size()) +
                                               " ranks) correlate reads the members slab by slab: --stream on or auto");
  StartingContext starting;  // the device starts while the members are read
  const auto t0 = std::chrono::steady_clock::now();
  if (a.stream != "off") {
    // Slab by slab: asked for, under MPI, or (auto) when the members would take over a quarter of
    // the memory budget and every member's format streams.
    const bool must = a.stream == "on" || distributed;
    EnsembleSlabs slabs = a.ensemble.empty() ? open_ensemble_member_slabs(member_files, vo, !must)
                                             : open_ensemble_slabs(a.ensemble, vo, !must);
    if (!slabs.members.empty()) {
      const uint64_t bytes = uint64_t(slabs.members.size()) * slabs.grid().voxel_count() * sizeof(float);
      if (must || bytes > memory_budget().bytes / 4) {
        if (!must && !globals().quiet)
          std::cerr << "tfmatch: reading the members slab by slab (" << format_bytes(bytes) << " as float32; memory budget "
                    << format_bytes(memory_budget().bytes) << ", " << memory_budget().source << ")\n";
        return run_streamed(a, params, json, outputs, starting, slabs, t0);
      }
    }
  }
  const Ensemble ens = a.ensemble.empty() ? load_ensemble_members(member_files, vo) : load_ensemble(a.ensemble, vo);
  const std::string source = ens.grid.name;
  check_correlation_members(ens);
  try {
    validate_correlation_params(params, ens.member_count);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(source + ": " + e.what());
  }
  CorrelationRequest request;
  request.params = params;
  request.absolute = a.absolute;
  const GridIndex p1 = resolve_point(ens.grid, a.point, "--point");
  request.point = linear_index(ens.grid, p1);
  std::optional<GridIndex> p2;
  if (!a.point2.empty()) {
    p2 = resolve_point(ens.grid, a.point2, "--point2");
    request.point2 = linear_index(ens.grid, *p2);
  }
  try {
    check_reference_point(ens.view(), request.point, params.measure);
    if (request.point2) check_reference_point(ens.view(), *request.point2, params.measure);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(source + ": " + e.what());
  }
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  auto ctx = starting.get();
  const auto t1 = std::chrono::steady_clock::now();
  Volume field = empty_like(ens.grid);
  field.name = field_name(a);
  {
    Progress progress(std::string(correlation_measure_name(params.measure)) + " over " +
                          std::to_string(ens.member_count) + " members",
                      ens.voxel_count() * (p2 ? 2 : 1));
    field.values = correlation_field(*ctx, ens.view(), request,
                                     [&](uint64_t done, uint64_t) { progress.update(done); });
  }
  const double compute_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();

  write_field(a, json, outputs, field, ens.grid, source, ens.member_count, params, p1, p2, ctx->device_name(), load_s,
              compute_s, {});
  return 0;
}

CommandRegistration reg(23, [](CLI::App& app) {
  auto args = std::make_shared<CorrelateArgs>();
  auto* sub = app.add_subcommand(
      "correlate",
      "Correlation field of an ensemble: per voxel, a measure between the member series at a reference point and "
      "at that voxel. A voxel where any member has no data (NaN, fill value) is NaN; a constant series gives NaN "
      "for pearson, spearman and kendall and 0 for the mutual-information measures");
  sub->add_option("--ensemble", args->ensemble,
                  "Ensemble: a NetCDF variable with a member dimension (member, members, ensemble, realization, number, "
                  "or --member-dim) or GRIB messages differing in `number`, as FILE[:VAR]");
  sub->add_option("--members", args->members, "Ensemble as one file per member (FILE[:VAR] ...; quoted patterns such as "
                                              "'run*/t.vti' are expanded in natural order: run2 before run10)");
  sub->add_option("--point", args->point,
                  "Reference point: I,J,K grid indices (I along x, the fastest axis) or lon=..,lat=..,level=.. "
                  "(nearest grid point, printed)")->required();
  sub->add_option("--point2", args->point2, "Second reference point: the output is corr(point) - corr(point2)");
  sub->add_option("--measure", args->measure, "pearson, spearman, kendall (tau-b), mi-binned, mi-kraskov or mi-coefficient")
      ->capture_default_str();
  sub->add_option("--bins", args->bins, "mi-binned: equal-width bins over each series' min..max")
      ->check(CLI::Range(2u, kMaxCorrelationBins))->capture_default_str();
  sub->add_option("--k", args->k, "mi-kraskov, mi-coefficient: neighbours of the KSG estimator (1 .. members-1)")
      ->check(positive())->capture_default_str();
  sub->add_flag("--abs", args->absolute, "Write the magnitude |result| (after the difference with --point2)");
  sub->add_option("--out", args->out, "Output field: .vti (origin and spacing kept), .raw (float32), or .pvti (ParaView "
                  "parallel image data: the .pvti and a directory of .vti pieces, one per MPI rank), same grid")
      ->required()->check(output_format(correlation_output_format()));
  add_json_option(sub, args->json, "what was computed");
  sub->add_option("--member-dim", args->member_dim, "NetCDF: the name of the member dimension");
  sub->add_option("--stream", args->stream, "Read the members slab by slab of z-slices, so memory does not grow with "
                  "the ensemble: on, off, or auto (when the members would take over a quarter of the memory budget "
                  "and every member's format streams; always under MPI)")
      ->check(CLI::IsMember({"auto", "on", "off"}))->capture_default_str();
  sub->add_option("--slab-slices", args->slab_slices, "Slab by slab: z-slices per slab (default: as many as a quarter of "
                  "the memory budget left holds for every member)")
      ->check(positive());
  add_volume_flags(sub, args->volume_flags, FieldSelectors::VarTime);
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
