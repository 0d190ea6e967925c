// `tfmatch bench-correlate`: correlation-field throughput (voxels per second) of the GPU kernels
// per measure and member count, beside the multi-threaded CPU implementation of the same methods
// (correlation_field_cpu, all cores) measured in the same run, as ratios; and the kernels alone on
// an ensemble already on the device (as an embedder holds it, and as a few lines of PyTorch on
// the GPU see it) beside the device's read bound for the same values.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <thread>

#include "bench_timing.h"
#include "cli.h"
#include "output_options.h"
#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/read_bound.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/correlation_reference.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/synthetic_ensemble.h"
#include "tfmatch/reference/correlation_cpu.h"

namespace tfm::cli {
namespace {

// The grid of the paper's 1000-member ensemble.
constexpr uint64_t kGrid[3] = {250, 352, 20};

struct BenchArgs {
  uint64_t voxels = kGrid[0] * kGrid[1] * kGrid[2];  // 1.76 M
  std::vector<uint32_t> members{10, 100, 1000};
  std::vector<std::string> measures = correlation_measure_names();
  // Members x voxels per member count: the whole grid at M = 10; 200 000 voxels at M = 100 and
  // 20 000 at M = 1000, so that the run takes minutes on lavapipe (--max-values 2000000000 for all of it).
  uint64_t max_values = 20'000'000;
  unsigned cpu_threads = 0;
  uint32_t bins = 16, k = 3;
  bool quick = false;
  bool members_given = false;  // --members was on the command line
  std::string json;
};

// The first `voxels` voxels (x fastest) of the synthetic ensemble (host/model/synthetic_ensemble.h)
// on the paper's grid, generated on just the z levels they need (the memory of those voxels alone:
// `--voxels 1 --members 10000` held 3.5 GB of whole slices), and the series at its reference point
// (the centre of its strongly dependent blob).
struct BenchEnsemble {
  std::vector<float> values;  // member-major, `voxels` per member
  std::vector<float> reference;
};
BenchEnsemble bench_ensemble(uint32_t members, uint64_t voxels) {
  const uint64_t slice = kGrid[0] * kGrid[1];
  const std::array<uint64_t, 3> dims{kGrid[0], kGrid[1], (voxels + slice - 1) / slice};
  // A copy: the blobs are a temporary, gone at the end of this statement.
  const auto centre = synthetic_ensemble_blobs(dims[0], dims[1], dims[2]).centre[0];  // synthetic_ensemble_reference
  uint64_t reference = 0;
  // (On a grid one level deep the centre 0.5 rounds up to level 1: the last level is taken.)
  for (int axis = 2; axis >= 0; --axis)
    reference = reference * dims[axis] + std::min<uint64_t>(std::lround(centre[axis]), dims[axis] - 1);
  return {synthetic_ensemble_voxels(dims[0], dims[1], dims[2], members, 0, voxels),
          synthetic_ensemble_voxels(dims[0], dims[1], dims[2], members, reference, reference + 1)};
}

// The ensemble on the device once (member-major float32), and the device's read bound for its
// values: FieldPairReadKernel over its two halves, every value read once with the voxel kernels'
// own loads (checked against the CPU's bit sums), 0 where the halves are under 1024 values.
struct ResidentEnsemble {
  Buffer values;
  double read_bytes_per_s = 0;
};
ResidentEnsemble upload_ensemble(Context& ctx, const EnsembleView& ens) {
  const uint64_t count = uint64_t(ens.member_count) * ens.voxel_count;
  ResidentEnsemble r{Buffer(ctx, count * sizeof(float), MemoryUsage::Device, "bench-correlate ensemble")};
  upload(ctx, r.values, ens.values, count * sizeof(float));
  const uint64_t half = count / 2 / 1024 * 1024;  // the second half starts 4 KiB-aligned
  if (half == 0) return r;
  const DeviceField a = DeviceField::adopt(ctx, r.values.handle(), r.values.offset(), half, "ensemble first half");
  const DeviceField b = DeviceField::adopt(ctx, r.values.handle(), r.values.offset() + half * sizeof(float), half,
                                           "ensemble second half");
  const std::array<uint32_t, 2> expected =
      field_pair_bit_sums({ens.values, half}, {ens.values + half, half});
  const FieldPairReadKernel kernel(ctx);
  kernel.run(a, b);  // the first run compiles the shader on lavapipe
  const double ms = warm_best_ms(3, [&] {
    double gpu_ms = -1.0;
    if (kernel.run(a, b, &gpu_ms) != expected)
      throw std::runtime_error("bench-correlate: the read-bound kernel's sums differ from the CPU's on " +
                               ctx.device_name());
    return gpu_ms;
  });
  r.read_bytes_per_s = double(2 * half) * sizeof(float) / (ms * 1e-3);
  return r;
}

// The kernels alone on the resident ensemble: GPU time of CorrelationKernel::record (the
// reference's tables written before), best of a warm run; its field must have the bits of
// compute()'s `expected` (the same kernels on the same numbers).
double resident_ms(Context& ctx, CorrelationKernel& kernel, const ResidentEnsemble& ens, uint64_t voxels,
                   std::span<const float> reference, const CorrelationParams& p, const std::vector<float>& expected) {
  const CorrelationReference ref = prepare_correlation_reference(reference, p);
  CorrelationTables tables;
  Buffer out(ctx, voxels * sizeof(float), MemoryUsage::Device, "bench-correlate field");
  {
    CommandBatch batch(ctx);
    record_correlation_tables(batch, ctx, ref, tables);
    batch.submit_and_wait();
  }
  const double ms = warm_best_ms(3, [&] {
    CommandBatch batch(ctx);
    const uint32_t t0 = batch.timestamp();
    kernel.record(batch, ens.values, voxels, ref, tables, out);
    const uint32_t t1 = batch.timestamp();
    batch.submit_and_wait();
    return batch.elapsed_ms(t0, t1);
  });
  std::vector<float> field(voxels);
  readback(ctx, out, field.data(), voxels * sizeof(float));
  if (std::memcmp(field.data(), expected.data(), voxels * sizeof(float)) != 0)
    throw std::runtime_error(std::string("bench-correlate: ") + correlation_measure_name(p.measure) +
                             " on the resident ensemble differs from compute()'s bits on " + ctx.device_name());
  return ms;
}

int run(BenchArgs a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  set_progress_enabled(!globals().quiet);
  FilePlan().output(json.file(), "--json").check();
  if (a.quick) {
    a.voxels = std::min<uint64_t>(a.voxels, 2000);
    if (!a.members_given) a.members = {10, 40};
  }
  std::vector<CorrelationParams> params;
  for (const std::string& name : a.measures) params.push_back({parse_correlation_measure(name), a.bins, a.k});
  auto ctx = make_context();
  if (!ctx->timestamps_supported()) throw std::runtime_error("this device has no timestamps; cannot benchmark");
  CorrelationKernel kernel(*ctx);
  const unsigned cpu_threads = a.cpu_threads ? a.cpu_threads : std::max(1u, std::thread::hardware_concurrency());
  std::printf("bench-correlate on %s: the first voxels (up to %llu, and at most %llu values = members x voxels)\n"
              "  of the synthetic ensemble on the paper's 250x352x20 grid, its reference point; bins %u, k %u.\n"
              "  GPU: wall time of CorrelationKernel::compute (gathering the chunks, transfers and kernels);\n"
              "  CPU: correlation_field_cpu, %u threads, same voxels;\n"
              "  resident: GPU time of the kernels alone on the ensemble already on the device, and that\n"
              "  as a fraction of the device's read bound for the ensemble's bytes (res/read).\n\n",
              ctx->device_name().c_str(), static_cast<unsigned long long>(a.voxels),
              static_cast<unsigned long long>(a.max_values), a.bins, a.k, cpu_threads);
  std::printf("%-14s %5s %9s  %-61s %13s %13s %7s %10s %14s %8s\n", "measure", "M", "voxels", "GPU strategy",
              "GPU voxels/s", "CPU voxels/s", "ratio", "max |G-C|", "res. voxels/s", "res/read");
  nlohmann::json results = nlohmann::json::array();
  for (uint32_t members : a.members) {
    const uint64_t voxels = std::max<uint64_t>(1, std::min(a.voxels, a.max_values / members));
    if (!globals().quiet) std::cerr << "generating " << members << " members x " << voxels << " voxels...\n";
    const BenchEnsemble b = bench_ensemble(members, voxels);
    const EnsembleView ens{b.values.data(), members, voxels};
    const std::vector<float>& reference = b.reference;
    const ResidentEnsemble resident = upload_ensemble(*ctx, ens);
    const double ensemble_bytes = double(members) * double(voxels) * sizeof(float);
    std::printf("  M = %u: %.3g values on the device, read bound %.3g GB/s\n", members, double(members) * double(voxels),
                resident.read_bytes_per_s / 1e9);
    for (const CorrelationParams& p : params) {
      const std::string name = correlation_measure_name(p.measure);
      const EnsembleView warm{b.values.data(), members, std::min<uint64_t>(voxels, 64)};
      kernel.compute(warm, ensemble_series(warm, 0), p);  // pipeline creation is not measured
      Progress progress(name + " M=" + std::to_string(members) + " GPU", voxels);
      auto t0 = std::chrono::steady_clock::now();
      const std::vector<float> gpu = kernel.compute(ens, reference, p, [&](uint64_t done, uint64_t) {
        checkpoint("correlate");
        progress.update(done);
      });
      const double gpu_s = seconds_since(t0);
      progress.set_label(name + " M=" + std::to_string(members) + " CPU");
      t0 = std::chrono::steady_clock::now();
      const std::vector<float> cpu = correlation_field_cpu(ens, reference, p, cpu_threads);
      const double cpu_s = seconds_since(t0);
      progress.finish();
      double diff = 0;
      for (uint64_t v = 0; v < voxels; ++v)
        if (!std::isnan(gpu[v]) || !std::isnan(cpu[v])) diff = std::max(diff, double(std::abs(gpu[v] - cpu[v])));
      const double gpu_rate = double(voxels) / gpu_s, cpu_rate = double(voxels) / cpu_s;
      const double res_ms = resident_ms(*ctx, kernel, resident, voxels, reference, p, gpu);
      const double res_rate = double(voxels) / (res_ms * 1e-3);
      // The fraction of the read bound: the ensemble's bytes over the kernels' time, over the bound.
      const double res_over_read =
          resident.read_bytes_per_s > 0 ? ensemble_bytes / (res_ms * 1e-3) / resident.read_bytes_per_s : 0.0;
      const std::string strategy = CorrelationKernel::strategy(p, members);
      std::printf("%-14s %5u %9llu  %-61s %13.4g %13.4g %7.2f %10.2g %14.4g %8.3f\n", name.c_str(), members,
                  static_cast<unsigned long long>(voxels), strategy.c_str(), gpu_rate, cpu_rate, gpu_rate / cpu_rate, diff,
                  res_rate, res_over_read);
      std::fflush(stdout);
      results.push_back({{"measure", name}, {"members", members}, {"voxels", voxels}, {"strategy", strategy},
                         {"gpu_s", gpu_s}, {"gpu_voxels_per_s", gpu_rate}, {"cpu_threads", cpu_threads}, {"cpu_s", cpu_s},
                         {"cpu_voxels_per_s", cpu_rate}, {"ratio", gpu_rate / cpu_rate}, {"max_abs_difference", diff},
                         {"resident_ms", res_ms}, {"resident_voxels_per_s", res_rate},
                         {"read_bound_bytes_per_s", resident.read_bytes_per_s},
                         {"resident_over_read_bound", res_over_read}});
    }
  }
  json.write({{"device", ctx->device_name()}, {"bins", a.bins}, {"k", a.k}, {"results", results}});
  return 0;
}

CommandRegistration reg(93, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand("bench-correlate",
                                 "Benchmark the correlation-field kernels against the multi-threaded CPU implementation");
  sub->add_option("--voxels", args->voxels, "The first voxels of the paper's 250x352x20 grid (default: all)")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 32))->capture_default_str();
  sub->add_option("--members", args->members, "Member counts, comma separated")->delimiter(',')
      ->check(CLI::Range(3u, 100000u))->capture_default_str();
  sub->add_option("--measures", args->measures, "Measures, comma separated")->delimiter(',')
      ->check(CLI::IsMember(correlation_measure_names()))->capture_default_str();
  sub->add_option("--max-values", args->max_values,
                  "At most this many values (members x voxels) per member count: fewer voxels for large M")
      ->check(CLI::Range(uint64_t(1000), uint64_t(1) << 36))->capture_default_str();
  sub->add_option("--cpu-threads", args->cpu_threads, "CPU threads (0: all cores)")
      ->check(CLI::Range(0u, 4096u))->capture_default_str();
  sub->add_option("--bins", args->bins, "mi-binned bins")->check(CLI::Range(2u, kMaxCorrelationBins))->capture_default_str();
  sub->add_option("--k", args->k, "mi-kraskov / mi-coefficient neighbours")->check(CLI::Range(1u, kMaxCorrelationK))
      ->capture_default_str();
  sub->add_flag("--quick", args->quick, "A sanity run: at most 2000 voxels; members 10 and 40 unless --members gives them");
  add_json_option(sub, args->json, "the results");
  sub->callback([args, sub] {
    args->members_given = sub->count("--members") > 0;  // --quick only replaces the default counts
    exit_code() = run(*args);
  });
});

}  // namespace
}  // namespace tfm::cli
