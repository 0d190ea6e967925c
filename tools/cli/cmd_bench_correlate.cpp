// `tfmatch bench-correlate`: correlation-field throughput (voxels per second) of the GPU kernels
// per measure and member count, beside the multi-threaded CPU implementation of the same methods
// (correlation_field_cpu, all cores) measured in the same run, as ratios.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <thread>

#include <nlohmann/json.hpp>

#include "atomic_file.h"
#include "cancellation.h"
#include "cli.h"
#include "correlation.h"
#include "correlation_cpu.h"
#include "output_check.h"
#include "progress.h"

namespace tfm::cli {
namespace {

struct BenchArgs {
  uint64_t voxels = 250ull * 352 * 20;  // the paper's 1000-member ensemble grid (1.76 M voxels)
  std::vector<uint32_t> members{10, 100, 1000};
  std::vector<std::string> measures = correlation_measure_names();
  uint64_t max_values = 200'000'000;  // members x voxels per run
  unsigned cpu_threads = 0;
  uint32_t bins = 16, k = 3;
  bool quick = false;
  std::string json;
};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Uniform in [0, 1) from a 64-bit hash of (a, b): the same ensemble on every run and thread count.
float hash_uniform(uint64_t a, uint64_t b) {
  uint64_t h = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E5A9ull + (a << 6) + (a >> 2));
  h ^= h >> 31;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 29;
  return float(h >> 40) * 0x1p-24f;
}

// A synthetic member-major ensemble: member m at voxel v mixes a member signal s_m (shared by all
// voxels) with noise, with a weight that varies smoothly over the grid, so voxels range from
// strongly dependent on the reference point to independent of it, as in a real ensemble.
std::vector<float> synthetic_ensemble(uint32_t members, uint64_t voxels) {
  std::vector<float> values(uint64_t(members) * voxels);
  auto fill = [&](uint32_t m0, uint32_t m1) {
    for (uint32_t m = m0; m < m1; ++m) {
      const float signal = hash_uniform(m, 0);
      for (uint64_t v = 0; v < voxels; ++v) {
        const float w = 0.5f + 0.5f * std::sin(float(v) * 1e-4f);
        values[m * voxels + v] = w * signal + (1 - w) * hash_uniform(m + 1, v);
      }
    }
  };
  const uint32_t threads = std::max(1u, std::min(members, std::thread::hardware_concurrency()));
  std::vector<std::thread> pool;
  for (uint32_t t = 0; t < threads; ++t) pool.emplace_back(fill, members * t / threads, members * (t + 1) / threads);
  for (std::thread& t : pool) t.join();
  return values;
}

int run(BenchArgs a) {
  set_progress_enabled(!globals().quiet);
  FilePlan().output(a.json == "-" ? "" : a.json, "--json").check();
  if (a.quick) {
    a.voxels = std::min<uint64_t>(a.voxels, 2000);
    a.members = {10, 40};
  }
  std::vector<CorrelationParams> params;
  for (const std::string& name : a.measures) params.push_back({parse_correlation_measure(name), a.bins, a.k});
  auto ctx = make_context();
  CorrelationKernel kernel(*ctx);
  const unsigned cpu_threads = a.cpu_threads ? a.cpu_threads : std::max(1u, std::thread::hardware_concurrency());
  std::printf("bench-correlate on %s: synthetic ensemble, reference at voxel 0, up to %llu voxels and at most\n"
              "  %llu values (members x voxels) per run; bins %u, k %u. GPU: wall time of CorrelationKernel::compute\n"
              "  (gathering the chunks, transfers and kernels); CPU: correlation_field_cpu, %u threads, same voxels.\n\n",
              ctx->device_name().c_str(), static_cast<unsigned long long>(a.voxels),
              static_cast<unsigned long long>(a.max_values), a.bins, a.k, cpu_threads);
  std::printf("%-14s %5s %9s  %-52s %13s %13s %7s %10s\n", "measure", "M", "voxels", "GPU strategy", "GPU voxels/s",
              "CPU voxels/s", "ratio", "max |G-C|");
  nlohmann::json results = nlohmann::json::array();
  for (uint32_t members : a.members) {
    const uint64_t voxels = std::max<uint64_t>(1, std::min(a.voxels, a.max_values / members));
    if (!globals().quiet) std::cerr << "generating " << members << " members x " << voxels << " voxels...\n";
    const std::vector<float> values = synthetic_ensemble(members, voxels);
    const EnsembleView ens{values.data(), members, voxels};
    const std::vector<float> reference = ensemble_series(ens, 0);
    for (const CorrelationParams& p : params) {
      const std::string name = correlation_measure_name(p.measure);
      const EnsembleView warm{values.data(), members, std::min<uint64_t>(voxels, 64)};
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
      const std::string strategy = CorrelationKernel::strategy(p, members);
      std::printf("%-14s %5u %9llu  %-52s %13.4g %13.4g %7.2f %10.2g\n", name.c_str(), members,
                  static_cast<unsigned long long>(voxels), strategy.c_str(), gpu_rate, cpu_rate, gpu_rate / cpu_rate, diff);
      std::fflush(stdout);
      results.push_back({{"measure", name}, {"members", members}, {"voxels", voxels}, {"strategy", strategy},
                         {"gpu_s", gpu_s}, {"gpu_voxels_per_s", gpu_rate}, {"cpu_threads", cpu_threads}, {"cpu_s", cpu_s},
                         {"cpu_voxels_per_s", cpu_rate}, {"ratio", gpu_rate / cpu_rate}, {"max_abs_difference", diff}});
    }
  }
  if (!a.json.empty()) {
    const nlohmann::json j{{"device", ctx->device_name()}, {"bins", a.bins}, {"k", a.k}, {"results", results}};
    if (a.json == "-")
      std::cout << j.dump(2) << "\n";
    else
      write_file_atomically(a.json, j.dump(2) + "\n");
  }
  return 0;
}

CommandRegistration reg(93, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand("bench-correlate",
                                 "Benchmark the correlation-field kernels against the multi-threaded CPU implementation");
  sub->add_option("--voxels", args->voxels, "Grid voxels (default: the paper's 250x352x20 grid)")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 32))->capture_default_str();
  sub->add_option("--members", args->members, "Member counts, comma separated")->delimiter(',')
      ->check(CLI::Range(3u, 100000u))->capture_default_str();
  sub->add_option("--measures", args->measures, "Measures, comma separated")->delimiter(',')
      ->check(CLI::IsMember(correlation_measure_names()))->capture_default_str();
  sub->add_option("--max-values", args->max_values,
                  "At most this many values (members x voxels) per member count: fewer voxels for large M")
      ->check(CLI::Range(uint64_t(1000), uint64_t(1) << 36))->capture_default_str();
  sub->add_option("--cpu-threads", args->cpu_threads, "CPU threads (0: all cores)")->capture_default_str();
  sub->add_option("--bins", args->bins, "mi-binned bins")->check(CLI::Range(2u, kMaxCorrelationBins))->capture_default_str();
  sub->add_option("--k", args->k, "mi-kraskov / mi-coefficient neighbours")->check(CLI::Range(1u, kMaxCorrelationK))
      ->capture_default_str();
  sub->add_flag("--quick", args->quick, "A sanity run: at most 2000 voxels, 10 and 40 members");
  sub->add_option("--json", args->json, "Also write the results as JSON (- for stdout)");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
