// run_optimize_streamed(): run_optimize() for fields read from disk slab by slab.
#include "tfmatch/solvers/streamed_optimize.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>
#include <span>
#include <stdexcept>
#include <tuple>

#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

// Calls fn(z0, nz, ref values, field values) for each slab of `slab_slices` z-slices of both fields
// within the z-slices [z_first, z_end) (all when z_end is 0), in z order. The next slab is read on
// another thread while fn works on this one (two host buffers per field), so the disk and the
// device overlap; a read's error or cancellation reaches the caller from the slab it belongs to.
template <class Fn>
void for_each_slab_pair(VolumeSlabReader& ref, VolumeSlabReader& field, uint64_t slab_slices, Fn fn,
                        uint64_t z_first = 0, uint64_t z_end = 0) {
  const uint64_t s = ref.slice_voxels(), nz = z_end ? z_end : ref.grid().dims[2];
  if (z_first >= nz) return;  // a rank beyond the slices
  const uint64_t capacity = std::min(slab_slices, nz - z_first) * s;
  const int buffers = nz - z_first > slab_slices ? 2 : 1;
  check_memory(2 * uint64_t(buffers) * capacity * sizeof(float),
               "streaming " + ref.grid().name + " and " + field.grid().name + " (" + std::to_string(capacity) +
                   " voxels per slab)");
  std::vector<float> a[2], b[2];
  for (int i = 0; i < buffers; ++i) a[i].resize(capacity), b[i].resize(capacity);
  auto read = [&](uint64_t z0, int slot) {
    const uint64_t n = std::min(slab_slices, nz - z0);
    ref.read_slices(z0, n, a[slot].data());
    field.read_slices(z0, n, b[slot].data());
  };
  checkpoint("stream");
  {
    PhaseScope timing(Phase::Read);
    read(z_first, 0);
  }
  int slot = 0;
  for (uint64_t z0 = z_first; z0 < nz; z0 += slab_slices, slot ^= 1) {
    const uint64_t n = std::min(slab_slices, nz - z0);
    std::future<void> next;  // its destructor waits for the read, also when fn throws
    if (z0 + slab_slices < nz)
      next = std::async(std::launch::async, [&, z = z0 + slab_slices, into = slot ^ 1] {
        const UntimedThread overlapped;  // counted as the time the loop below waits for it
        read(z, into);
      });
    fn(z0, n, std::span<const float>(a[slot].data(), n * s), std::span<const float>(b[slot].data(), n * s));
    if (next.valid()) {
      PhaseScope timing(Phase::Read);  // what the read did not hide behind the slab's work
      next.get();
    }
    checkpoint("stream");
  }
}

// The device fields a slab is uploaded to: one pair of the full slab's size, one for a shorter
// last slab (made when needed).
class SlabUploader {
 public:
  SlabUploader(Context& ctx, uint64_t slab_voxels, uint64_t max_chunk_voxels)
      : ctx_(ctx), max_chunk_(max_chunk_voxels) {
    check_device_memory(ctx, 2 * slab_voxels * sizeof(float), "a slab of both fields");
    full_ = make(slab_voxels);
  }
  // The pair holding (ref, field) after uploading them.
  const std::pair<DeviceField, DeviceField>& upload(std::span<const float> ref, std::span<const float> field) {
    std::unique_ptr<std::pair<DeviceField, DeviceField>>& target = ref.size() == full_->first.voxel_count() ? full_ : tail_;
    if (!target || target->first.voxel_count() != ref.size()) target = make(ref.size());
    target->first.upload(ref);
    target->second.upload(field);
    return *target;
  }

 private:
  std::unique_ptr<std::pair<DeviceField, DeviceField>> make(uint64_t voxels) {
    return std::make_unique<std::pair<DeviceField, DeviceField>>(
        std::piecewise_construct, std::forward_as_tuple(ctx_, voxels, "reference slab", max_chunk_),
        std::forward_as_tuple(ctx_, voxels, "second field slab", max_chunk_));
  }
  Context& ctx_;
  uint64_t max_chunk_;
  std::unique_ptr<std::pair<DeviceField, DeviceField>> full_, tail_;
};

// The smallest box edge k whose downsampled grid, ceil(n / k) per axis, has at most `budget` voxels.
uint64_t box_factor(const std::array<uint64_t, 3>& dims, uint64_t budget) {
  uint64_t k = 1;
  auto voxels = [&](uint64_t f) {
    uint64_t n = 1;
    for (uint64_t d : dims) n *= (d + f - 1) / f;
    return n;
  };
  while (voxels(k) > budget) ++k;
  return k;
}

// A box-filtered copy built slab by slab: the mean of each k^3 box's finite values (NaN: none).
class BoxFilter {
 public:
  BoxFilter(const Volume& grid, uint64_t k) : k_(k), dims_(grid.dims) {
    out_ = empty_like(grid);
    out_.axes = {};  // the file's coordinates are per original index
    for (int a = 0; a < 3; ++a) {
      out_.dims[a] = (dims_[a] + k - 1) / k;
      out_.origin[a] = grid.origin[a] + 0.5 * double(k - 1) * grid.spacing[a];
      out_.spacing[a] = grid.spacing[a] * double(k);
    }
    check_memory(out_.voxel_count() * (sizeof(double) + sizeof(uint32_t) + sizeof(float)),
                 "the downsampled copy of " + grid.name);
    sums_.assign(out_.voxel_count(), 0.0);
    counts_.assign(out_.voxel_count(), 0);
  }
  void add(uint64_t z0, uint64_t nz, std::span<const float> values) {
    const uint64_t nx = dims_[0], ny = dims_[1], ox = out_.dims[0], oy = out_.dims[1];
    for (uint64_t z = 0; z < nz; ++z)
      for (uint64_t y = 0; y < ny; ++y) {
        const float* row = values.data() + (z * ny + y) * nx;
        const uint64_t base = ((z0 + z) / k_ * oy + y / k_) * ox;
        for (uint64_t x = 0; x < nx; ++x)
          if (std::isfinite(row[x])) sums_[base + x / k_] += row[x], ++counts_[base + x / k_];
      }
  }
  // Adds the sums and counts of every rank's boxes: with ranks on whole boxes of z-slices each
  // box's sums come from one rank, so the others add exact zeros.
  void reduce(Ranks& ranks) {
    ranks.sum(std::span<double>(sums_));
    std::vector<uint64_t> counts(counts_.begin(), counts_.end());
    ranks.sum(std::span<uint64_t>(counts));
    for (size_t i = 0; i < counts.size(); ++i) counts_[i] = uint32_t(counts[i]);
  }
  Volume finish() {
    out_.values.resize(sums_.size());
    for (size_t i = 0; i < sums_.size(); ++i) out_.values[i] = counts_[i] ? float(sums_[i] / counts_[i]) : NAN;
    sums_ = {};
    counts_ = {};
    return std::move(out_);
  }

 private:
  uint64_t k_;
  std::array<uint64_t, 3> dims_;
  Volume out_;
  std::vector<double> sums_;
  std::vector<uint32_t> counts_;
};

// Finite min/max of both fields and how much of them lies outside the ranges given up front.
struct FieldMeasures {
  FiniteStats ref, field;
  RangeCoverage ref_coverage, field_coverage;
  // The measures of all ranks' slices together.
  void reduce(Ranks& ranks) {
    if (ranks.size() == 1) return;
    std::array<double, 2> lo{ref.finite ? ref.lo : INFINITY, field.finite ? field.lo : INFINITY};
    std::array<double, 2> hi{ref.finite ? ref.hi : -INFINITY, field.finite ? field.hi : -INFINITY};
    std::array<uint64_t, 10> counts{ref.finite,         ref.nan,           field.finite,          field.nan,
                                    ref_coverage.finite, ref_coverage.below, ref_coverage.above,   field_coverage.finite,
                                    field_coverage.below, field_coverage.above};
    ranks.min(lo);
    ranks.max(hi);
    ranks.sum(std::span<uint64_t>(counts));
    ref = {counts[0] ? lo[0] : 0.0, counts[0] ? hi[0] : 0.0, counts[0], counts[1]};
    field = {counts[2] ? lo[1] : 0.0, counts[2] ? hi[1] : 0.0, counts[2], counts[3]};
    ref_coverage = {counts[4], counts[5], counts[6]};
    field_coverage = {counts[7], counts[8], counts[9]};
  }
  void add(std::span<const float> r, std::span<const float> f, const FieldRange* ref_user, const FieldRange* field_user) {
    ref = merge(ref, finite_stats(r));
    field = merge(field, finite_stats(f));
    if (ref_user) ref_coverage += range_coverage(r, *ref_user);
    if (field_user) field_coverage += range_coverage(f, *field_user);
  }
};

}  // namespace

const std::vector<std::string>& streaming_solvers() {
  static const std::vector<std::string> names{"normal-equations", "qp"};
  return names;
}

bool solver_streams(std::string_view solver) {
  const auto& n = streaming_solvers();
  return std::find(n.begin(), n.end(), solver) != n.end();
}

namespace {
// The slab-by-slab assembly into `gpu` (reset first).
void assemble_slabs(Context& ctx, GpuNormalEquations& gpu, VolumeSlabReader& ref, VolumeSlabReader& field,
                    const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                    uint64_t slab_slices, uint64_t max_chunk_voxels, const FieldMapping* before_map) {
  require_same_grid(ref.grid(), field.grid());
  slab_slices = std::clamp<uint64_t>(slab_slices, 1, ref.grid().dims[2]);
  SlabUploader device(ctx, slab_slices * ref.slice_voxels(), max_chunk_voxels);
  gpu.reset();
  for_each_slab_pair(ref, field, slab_slices, [&](uint64_t, uint64_t, std::span<const float> r, std::span<const float> f) {
    const auto& d = device.upload(r, f);
    gpu.add(d.first, d.second, ref_map, opt_map, ref_tf, before_map);
  });
}
}  // namespace

NormalEquations assemble_streamed(Context& ctx, VolumeSlabReader& ref, VolumeSlabReader& field,
                                  const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                                  uint64_t slab_slices, uint64_t max_chunk_voxels) {
  GpuNormalEquations gpu(ctx, opt_map.tf_size);
  assemble_slabs(ctx, gpu, ref, field, ref_map, opt_map, ref_tf, slab_slices, max_chunk_voxels, nullptr);
  return gpu.result();
}

std::vector<uint64_t> assemble_streamed_slots(Context& ctx, GpuNormalEquations& gpu, VolumeSlabReader& ref,
                                              VolumeSlabReader& field, const FieldMapping& ref_map,
                                              const FieldMapping& opt_map, const Buffer& ref_tf, uint64_t slab_slices,
                                              const FieldMapping* before_map, uint64_t max_chunk_voxels) {
  assemble_slabs(ctx, gpu, ref, field, ref_map, opt_map, ref_tf, slab_slices, max_chunk_voxels, before_map);
  return gpu.fixed_point_slots();
}

FiniteStats streamed_finite_stats(VolumeSlabReader& volume, uint64_t slab_slices) {
  const uint64_t nz = volume.grid().dims[2];
  slab_slices = std::clamp<uint64_t>(slab_slices, 1, nz);
  std::vector<float> slab(slab_slices * volume.slice_voxels());
  FiniteStats stats{};
  for (uint64_t z0 = 0; z0 < nz; z0 += slab_slices) {
    checkpoint("stream");
    const uint64_t n = std::min(slab_slices, nz - z0);
    volume.read_slices(z0, n, slab.data());
    stats = merge(stats, finite_stats(std::span<const float>(slab.data(), n * volume.slice_voxels())));
  }
  return stats;
}

StreamedOptimizeResult run_optimize_streamed(Context& ctx, const StreamedOptimizeRequest& req) {
  if (!req.ref || !req.field) throw std::invalid_argument("run_optimize_streamed: both fields are required");
  if (req.tf_size < 2) throw std::runtime_error(parameter("tf-size") + " must be at least 2");
  if (!solver_streams(req.solver))
    throw std::runtime_error("solver " + req.solver + " needs both fields in memory; the solvers that stream from "
                             "disk are normal-equations and qp (they work from the assembled system alone)");
  const Solver& solver = require_solver(req.solver);
  SolverSettings settings = req.settings;
  settings.solve.streamed = true;
  const SolverArgs args = parse_solver_args(solver, settings);
  if (args.has("weights") && args.text("weights") != "none")
    throw std::runtime_error(parameter("weights") + " " + args.text("weights") +
                             " renders the whole reference field on the device: it does not stream from disk "
                             "(the fields must fit in memory, " + parameter("stream") + " off, in one process)");
  VolumeSlabReader& ref = *req.ref;
  VolumeSlabReader& field = *req.field;
  require_same_grid(ref.grid(), field.grid());
  const Volume& grid = ref.grid();

  StreamedOptimizeResult s;
  OptimizeResult& out = s.result;
  out.solver = req.solver;
  out.device = ctx.device_name();
  out.voxels_total = grid.voxel_count();
  if (std::string w = grid_geometry_warning(grid, field.grid()); !w.empty()) out.warnings.push_back(std::move(w));
  s.streamed = ref.streams() && field.streams();
  Ranks& ranks = req.ranks ? *req.ranks : single_rank();
  require_same_grid_on_every_rank(ranks, grid, ref.grid().name + " and " + field.grid().name);
  // This rank's work, then the agreement: a failure on any rank stops every rank (ranks.h).
  auto on_every_rank = [&](auto&& work) {
    std::exception_ptr failed;
    try {
      work();
    } catch (...) {
      failed = std::current_exception();
    }
    ranks.agree(failed);
  };

  // The assembly's kernel and the reference TF on the device. The kernel runs once on one voxel
  // before the slabs are sized from the memory left: a driver may compile a pipeline's code at its
  // first dispatch (lavapipe does, and its compiler's memory stays), which would otherwise come
  // on top of slabs sized without it (a 160 MiB budget peaked at 215 MiB on a cold shader cache).
  Buffer ref_tf_buffer;
  std::optional<GpuNormalEquations> gpu;
  const bool with_before = req.ref_tf.size() != req.tf_size;
  on_every_rank([&] {
    ref_tf_buffer = upload_tf(ctx, req.ref_tf, "reference TF");
    gpu.emplace(ctx, req.tf_size);
    const float one_voxel = 0.5f;
    const DeviceField ref_voxel(ctx, std::span<const float>(&one_voxel, 1), "warm-up voxel");
    const DeviceField opt_voxel(ctx, std::span<const float>(&one_voxel, 1), "warm-up voxel");
    const FieldMapping on_ref_tf = make_mapping(FieldRange{}, static_cast<uint32_t>(req.ref_tf.size()));
    gpu->add(ref_voxel, opt_voxel, on_ref_tf, make_mapping(FieldRange{}, req.tf_size), ref_tf_buffer,
             with_before ? &on_ref_tf : nullptr);
    gpu->reset();
  });

  uint64_t slab_voxels = req.slab_voxels;
  if (slab_voxels == 0) {
    // Two host buffers (one read ahead) and a device field per field: 24 bytes per slab voxel;
    // a quarter of what the budget leaves beside the context's staging memory (not yet resident
    // before the first upload).
    const uint64_t held = resident_memory() + kStagingBytes, budget = memory_budget().bytes;
    const uint64_t left = budget > held ? budget - held : 0;
    slab_voxels = std::clamp<uint64_t>(left / 4 / 24, uint64_t(1) << 16, kDefaultSlabVoxels);
  }
  s.slab_slices = std::clamp<uint64_t>(slab_voxels / ref.slice_voxels(), 1, grid.dims[2]);

  // Ranks take whole preview boxes of z-slices, so each box's sums come from one rank.
  if (req.preview_voxels) s.preview_factor = box_factor(grid.dims, req.preview_voxels);
  std::tie(s.first_slice, s.end_slice) =
      rank_slices(grid.dims[2], ranks.rank(), ranks.size(), req.preview_voxels ? s.preview_factor : 1);
  // Slabs of at most this rank's share (what it reads; the reads end at end_slice either way).
  s.slab_slices = std::min(s.slab_slices, std::max<uint64_t>(1, s.end_slice - s.first_slice));
  s.slabs = (s.end_slice - s.first_slice + s.slab_slices - 1) / s.slab_slices;

  const FieldRange* ref_user = req.ref_range ? &*req.ref_range : (req.ref_tf.range ? &*req.ref_tf.range : nullptr);
  const FieldRange* field_user = req.field_range ? &*req.field_range : nullptr;
  const std::string ref_source = req.ref_range ? "the given reference range" : "the reference TF file's range";
  FieldMeasures measures;
  // Ranges from the data need a pass of their own before the assembly; given ones are checked
  // against the data during the assembly pass.
  const bool range_pass = !ref_user || !field_user;
  s.passes = range_pass ? 2 : 1;
  auto t0 = std::chrono::steady_clock::now();
  if (range_pass) {
    on_every_rank([&] {
      for_each_slab_pair(
          ref, field, s.slab_slices,
          [&](uint64_t, uint64_t, std::span<const float> r, std::span<const float> f) {
            measures.add(r, f, ref_user, field_user);
          },
          s.first_slice, s.end_slice);
    });
    measures.reduce(ranks);
    out.phases.push_back({"range pass", ms_since(t0), -1.0});
  }
  out.ref_range = resolve_range(measures.ref, ref_user, ref.grid().name);
  out.field_range = resolve_range(measures.field, field_user, field.grid().name);
  auto check_coverage = [&] {
    if (ref_user) {
      std::string w = check_range_coverage(measures.ref_coverage, measures.ref, out.ref_range, ref.grid().name, ref_source,
                                           req.allow_out_of_range);
      if (!w.empty()) out.warnings.push_back(std::move(w));
    }
    if (field_user) {
      std::string w = check_range_coverage(measures.field_coverage, measures.field, out.field_range, field.grid().name,
                                           "the given field range", req.allow_out_of_range);
      if (!w.empty()) out.warnings.push_back(std::move(w));
    }
  };
  if (range_pass) check_coverage();

  // The assembly pass: the system for the optimized TF's size (with the loss before when the
  // reference TF has another size) and the downsampled copies.
  t0 = std::chrono::steady_clock::now();
  const FieldMapping ref_map = make_mapping(out.ref_range, static_cast<uint32_t>(req.ref_tf.size()));
  const FieldMapping opt_map = make_mapping(out.field_range, req.tf_size);
  const FieldMapping opt_with_ref_tf = make_mapping(out.field_range, static_cast<uint32_t>(req.ref_tf.size()));
  const FieldMapping* before_map = opt_with_ref_tf.tf_size != opt_map.tf_size ? &opt_with_ref_tf : nullptr;
  std::optional<BoxFilter> ref_box, field_box;
  double gpu_ms = 0.0;
  on_every_rank([&] {
    if (req.preview_voxels) {
      ref_box.emplace(ref.grid(), s.preview_factor);
      field_box.emplace(field.grid(), s.preview_factor);
    }
    SlabUploader device(ctx, s.slab_slices * ref.slice_voxels(), req.max_chunk_voxels);
    for_each_slab_pair(
        ref, field, s.slab_slices,
        [&](uint64_t z0, uint64_t nz, std::span<const float> r, std::span<const float> f) {
          if (!range_pass) measures.add(r, f, ref_user, field_user);
          const auto& d = device.upload(r, f);
          const double ms = gpu->add(d.first, d.second, ref_map, opt_map, ref_tf_buffer, before_map);
          gpu_ms = ms >= 0 && gpu_ms >= 0 ? gpu_ms + ms : -1.0;
          if (ref_box) ref_box->add(z0, nz, r), field_box->add(z0, nz, f);
        },
        s.first_slice, s.end_slice);
  });
  out.phases.push_back({"read+assemble", ms_since(t0), gpu_ms});
  // Every rank's integer words added: the same bits as one process's (exact sums).
  std::vector<uint64_t> slots = gpu->fixed_point_slots();
  ranks.sum(std::span<uint64_t>(slots));
  if (!range_pass) {
    measures.reduce(ranks);
    check_coverage();
  }
  if (ref_box) {
    if (ranks.size() > 1) ref_box->reduce(ranks), field_box->reduce(ranks);
    s.ref_preview = ref_box->finish(), s.field_preview = field_box->finish();
  }
  const NormalEquations eq = gpu->decode(slots, before_map != nullptr);
  if (eq.voxels == 0) throw std::runtime_error("no voxel has data in both " + ref.grid().name + " and " + field.grid().name);

  // The solver sees the assembled system; the device fields it could read are placeholders
  // (normal-equations and qp read only the system).
  const Volume& ref_volume = ref_box ? s.ref_preview : ref.grid();
  const Volume& opt_volume = field_box ? s.field_preview : field.grid();
  const float nothing = 0.0f;
  DeviceField ref_placeholder(ctx, std::span<const float>(&nothing, 1), "reference (streamed)");
  DeviceField opt_placeholder(ctx, std::span<const float>(&nothing, 1), "second field (streamed)");
  VoxelProblem problem{ctx,     ref_volume,          opt_volume,          ref_placeholder,
                       opt_placeholder, ref_map,     opt_map,             req.ref_tf,
                       ref_tf_buffer,   req.ref_tf.resampled(req.tf_size)};
  problem.system = eq;
  checkpoint("solve");
  SolverOutput solved = solver.solve(problem, args);
  for (auto& p : solved.phases) out.phases.push_back(p);
  out.warnings.insert(out.warnings.end(), solved.warnings.begin(), solved.warnings.end());
  out.details = solved.details;
  out.details["streamed"] = s.streamed ? "yes" : "no (a field was loaded whole)";
  out.details["passes"] = s.passes;
  out.details["slab_slices"] = s.slab_slices;
  out.tf = solved.tf;
  out.tf.range = out.field_range;
  if (auto w = unreferenced_entries_warning(eq, out.tf, args.solve, out.warnings)) out.warnings.push_back(*w);

  t0 = std::chrono::steady_clock::now();
  const std::vector<float> ref_entries = req.ref_tf.as_floats();
  out.before = voxel_loss_before(eq, ref_entries);
  out.phases.push_back({"loss before", ms_since(t0), -1.0});
  t0 = std::chrono::steady_clock::now();
  out.after = voxel_loss_from_system(eq, out.tf.as_floats());
  out.phases.push_back({"loss after", ms_since(t0), -1.0});
  return s;
}

}  // namespace tfm
