// run_optimize_series(): many fields against one reference (series_optimize.h).
#include "tfmatch/solvers/series_optimize.h"

#include <algorithm>
#include <chrono>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include "tfmatch/engine/vk_check.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/ranks.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {

namespace {

// `total` += `part` per channel: the losses of several fields' voxels together.
void add_loss(VoxelLoss& total, const VoxelLoss& part) {
  for (int c = 0; c < 4; ++c) {
    total.squared[size_t(c)] += part.squared[size_t(c)];
    total.absolute[size_t(c)] += part.absolute[size_t(c)];
  }
  total.voxels += part.voxels;
}

// "field k of n": how messages name a field of the series (its first is field 1; its TF file and
// table row are numbered from 0).
std::string field_label(const SeriesRequest& req, size_t i) {
  return "field " + std::to_string(i + 1) + " of " + std::to_string(req.field_count);
}

// Runs the work of field i: an error it raises names the field ("field 2 of 5: f.nc:T,time=1: the
// field has no finite value"), since a series may read every field from one file. Errors that the
// command line reports by their kind (the driver's, the memory budget's, another rank's) pass as
// they are; so does a cancellation (not a std::exception).
template <class Work>
auto for_field(const SeriesRequest& req, size_t i, Work&& work) {
  try {
    return work();
  } catch (const VulkanError&) {
    throw;
  } catch (const MemoryBudgetExceeded&) {
    throw;
  } catch (const RankFailure&) {
    throw;
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(field_label(req, i) + ": " + e.what());
  }
}

// Field i, loaded, on the reference's grid (else the error says every field needs it).
Volume load_checked(const SeriesRequest& req, size_t i) {
  Volume v = req.load_field(i);
  try {
    require_same_grid(*req.ref, v);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string(e.what()) + " (every field is fitted against the one reference)");
  }
  return v;
}

// Field i opened for a streamed fit, on the reference's grid (else the error names it).
std::unique_ptr<VolumeSlabReader> open_checked(const SeriesRequest& req, const VolumeSlabReader& ref, size_t i) {
  std::unique_ptr<VolumeSlabReader> f = req.open_field_slabs(i);
  try {
    require_same_grid(ref.grid(), f->grid());
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string(e.what()) + " (every field is fitted against the one reference)");
  }
  return f;
}

uint64_t slab_slices(const SeriesRequest& req, const VolumeSlabReader& ref) {
  const uint64_t voxels = req.slab_voxels ? req.slab_voxels : kDefaultSlabVoxels;
  return std::max<uint64_t>(1, voxels / ref.slice_voxels());
}

SeriesResult per_field(Context& ctx, const SeriesRequest& req) {
  SeriesResult out;
  out.solver = req.solver;
  out.device = ctx.device_name();
  if (req.streamed()) {
    for (size_t i = 0; i < req.field_count; ++i) {
      checkpoint("series");
      std::unique_ptr<VolumeSlabReader> ref = req.open_ref_slabs();
      const auto [name, one] = for_field(req, i, [&] {
        std::unique_ptr<VolumeSlabReader> field = open_checked(req, *ref, i);
        StreamedOptimizeRequest r;
        static_cast<FitSettings&>(r) = req;
        r.ref = ref.get();
        r.field = field.get();
        r.slab_voxels = req.slab_voxels;
        return std::pair{field->grid().name, run_optimize_streamed(ctx, r).result};
      });
      out.ref_range = one.ref_range;
      out.fields.push_back({name, one.field_range, one.tf, one.before, one.after, one.warnings});
      add_loss(out.before, one.before);
      add_loss(out.after, one.after);
    }
    return out;
  }
  for (size_t i = 0; i < req.field_count; ++i) {
    checkpoint("series");
    const auto [name, one] = for_field(req, i, [&] {
      const Volume field = load_checked(req, i);
      OptimizeRequest r;
      static_cast<FitSettings&>(r) = req;
      r.ref = req.ref;
      r.field = &field;
      return std::pair{field.name, run_optimize(ctx, r)};
    });
    out.ref_range = one.ref_range;
    out.fields.push_back({name, one.field_range, one.tf, one.before, one.after, one.warnings});
    add_loss(out.before, one.before);
    add_loss(out.after, one.after);
  }
  return out;
}

SeriesResult shared(Context& ctx, const SeriesRequest& req) {
  if (!solver_fits_shared(req.solver))
    throw std::runtime_error("solver " + req.solver + " fits one field at a time; one TF shared by all fields is "
                             "fitted from their summed system by normal-equations or qp");
  const Solver& solver = require_solver(req.solver);
  const SolverArgs args = parse_solver_args(solver, req.settings);
  if (args.has("weights") && args.text("weights") != "none")
    throw std::runtime_error(parameter("weights") + " " + args.text("weights") +
                             " weights one field's voxels; a shared TF is fitted without weights");
  SeriesResult out;
  out.shared_tf = true;
  out.solver = req.solver;
  out.device = ctx.device_name();
  // The reference: in memory, or its grid alone when streamed (read again for each field).
  std::unique_ptr<VolumeSlabReader> ref_reader = req.streamed() ? req.open_ref_slabs() : nullptr;
  const Volume& ref_grid = ref_reader ? ref_reader->grid() : *req.ref;
  const uint64_t slices = ref_reader ? slab_slices(req, *ref_reader) : 0;
  const FieldRange* ref_user = req.ref_range ? &*req.ref_range : (req.ref_tf.range ? &*req.ref_tf.range : nullptr);
  std::vector<std::string> warnings;
  if (ref_reader) {
    out.ref_range = ref_user ? *ref_user : resolve_range(streamed_finite_stats(*ref_reader, slices), nullptr, ref_grid.name);
  } else {
    out.ref_range = resolve_range(req.ref->values, ref_user, req.ref->name);
    if (ref_user) {
      const std::string source = req.ref_range ? "the given reference range" : "the reference TF file's range";
      std::string w = check_range_coverage(req.ref->values, out.ref_range, req.ref->name, source, req.allow_out_of_range);
      if (!w.empty()) warnings.push_back(std::move(w));
    }
  }

  // The one range every field maps through: given, or the union of the fields' own.
  auto t0 = std::chrono::steady_clock::now();
  FieldRange range{0.0, 0.0};
  if (req.field_range) {
    range = *req.field_range;
  } else {
    for (size_t i = 0; i < req.field_count; ++i) {
      checkpoint("series");
      const FieldRange r = for_field(req, i, [&] {
        if (ref_reader) {
          std::unique_ptr<VolumeSlabReader> field = open_checked(req, *ref_reader, i);
          return resolve_range(streamed_finite_stats(*field, slices), nullptr, field->grid().name);
        }
        const Volume field = load_checked(req, i);
        return resolve_range(field.values, nullptr, field.name);
      });
      range = i == 0 ? r : FieldRange{std::min(range.lo, r.lo), std::max(range.hi, r.hi)};
    }
    out.phases.push_back({"ranges", ms_since(t0), -1.0});
  }

  // Each field's system, and their exact sum.
  t0 = std::chrono::steady_clock::now();
  const Buffer ref_tf_buffer = upload_tf(ctx, req.ref_tf, "reference TF");
  const FieldMapping ref_map = make_mapping(out.ref_range, uint32_t(req.ref_tf.size()));
  const FieldMapping opt_map = make_mapping(range, req.tf_size);
  const FieldMapping before_map = make_mapping(range, uint32_t(req.ref_tf.size()));
  const FieldMapping* before = before_map.tf_size != opt_map.tf_size ? &before_map : nullptr;
  GpuNormalEquations gpu(ctx, req.tf_size);
  std::optional<DeviceField> ref;
  if (!ref_reader) {
    check_device_memory(ctx, 2 * req.ref->values.size() * sizeof(float), "the reference and one field");
    ref.emplace(ctx, req.ref->values, "reference field", req.max_chunk_voxels);
  }
  std::vector<uint64_t> total;
  std::vector<NormalEquations> systems;
  for (size_t i = 0; i < req.field_count; ++i) {
    checkpoint("series");
    SeriesFieldResult fr;
    fr.field_range = range;
    const std::vector<uint64_t> slots = for_field(req, i, [&] {
      if (ref_reader) {
        std::unique_ptr<VolumeSlabReader> reference = req.open_ref_slabs();
        std::unique_ptr<VolumeSlabReader> field = open_checked(req, *reference, i);
        fr.name = field->grid().name;
        return assemble_streamed_slots(ctx, gpu, *reference, *field, ref_map, opt_map, ref_tf_buffer, slices, before,
                                       req.max_chunk_voxels);
      }
      const Volume field = load_checked(req, i);
      fr.name = field.name;
      if (req.field_range) {
        std::string w =
            check_range_coverage(field.values, range, field.name, "the given field range", req.allow_out_of_range);
        if (!w.empty()) fr.warnings.push_back(std::move(w));
      }
      const DeviceField opt(ctx, field.values, "series field", req.max_chunk_voxels);
      gpu.reset();
      gpu.add(*ref, opt, ref_map, opt_map, ref_tf_buffer, before);
      return gpu.fixed_point_slots();
    });
    if (total.empty()) total.assign(slots.size(), 0);
    for (size_t k = 0; k < slots.size(); ++k) total[k] += slots[k];  // modulo 2^64, as on the device
    systems.push_back(gpu.decode(slots, before != nullptr));
    if (systems.back().voxels == 0)
      throw std::runtime_error(field_label(req, i) + ": no voxel has data in both " + ref_grid.name + " and " + fr.name);
    out.fields.push_back(std::move(fr));
  }
  out.phases.push_back({"assemble", ms_since(t0), -1.0});

  // The summed system, solved by the solver as streamed fits are: it reads only the system.
  const float nothing = 0.0f;
  const DeviceField ref_placeholder(ctx, std::span<const float>(&nothing, 1), "reference (series)");
  const DeviceField opt_placeholder(ctx, std::span<const float>(&nothing, 1), "fields (series)");
  VoxelProblem problem{ctx,      ref_grid, ref_grid,    ref_placeholder, opt_placeholder,
                       ref_map,  opt_map,  req.ref_tf, ref_tf_buffer,   req.ref_tf.resampled(req.tf_size)};
  problem.system = gpu.decode(total, before != nullptr);
  checkpoint("solve");
  SolverOutput solved = solver.solve(problem, args);
  for (auto& p : solved.phases) out.phases.push_back(p);
  warnings.insert(warnings.end(), solved.warnings.begin(), solved.warnings.end());
  out.details = solved.details;
  out.tf = solved.tf;
  out.tf.range = range;
  if (auto w = unreferenced_entries_warning(*problem.system, out.tf, args.solve, warnings)) warnings.push_back(*w);

  const std::vector<float> ref_rgba = req.ref_tf.as_floats(), tf_rgba = out.tf.as_floats();
  for (size_t i = 0; i < systems.size(); ++i) {
    SeriesFieldResult& fr = out.fields[i];
    fr.tf = out.tf;
    fr.before = voxel_loss_before(systems[i], ref_rgba);
    fr.after = voxel_loss_from_system(systems[i], tf_rgba);
    add_loss(out.before, fr.before);
    add_loss(out.after, fr.after);
  }
  out.warnings = std::move(warnings);
  return out;
}

}  // namespace

// The solvers that work from the assembled system alone: those that stream.
bool solver_fits_shared(std::string_view solver) { return solver_streams(solver); }

SeriesResult run_optimize_series(Context& ctx, const SeriesRequest& req) {
  if (req.streamed() ? !req.open_field_slabs : (!req.ref || !req.load_field))
    throw std::invalid_argument("run_optimize_series: the reference and the fields are required");
  if (req.field_count == 0) throw std::runtime_error("no fields to fit");
  if (req.tf_size < 2) throw std::runtime_error(parameter("tf-size") + " must be at least 2");
  SeriesResult out = req.shared_tf ? shared(ctx, req) : per_field(ctx, req);
  // A field given twice (a pattern and a file it matches, a range overlapping another) is fitted
  // twice: said once per repeated field, not an error (the rows stay as the fields were given).
  std::map<std::string, size_t> first;
  for (size_t i = 0; i < out.fields.size(); ++i) {
    const auto [at, inserted] = first.emplace(out.fields[i].name, i);
    if (!inserted)
      out.warnings.push_back(field_label(req, i) + " is field " + std::to_string(at->second + 1) + " again (" +
                             out.fields[i].name + "): it is fitted twice");
  }
  return out;
}

}  // namespace tfm
