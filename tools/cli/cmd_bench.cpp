// `tfmatch bench`: normal-equation assembly on the paper's data sizes at several TF sizes, beside
// what it is measured against, all in one run: a plain multi-threaded CPU loop of the same math
// (every core, double accumulators), this device's buffer-copy speed for the bytes the kernel
// reads, its speed at the kernel's own loads (kernels/read_bound.h), and the paper's CPU
// baseline (explicit sparse A with Eigen, A^T A and A^T b).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <thread>

#include "bench_timing.h"
#include "cli.h"
#include "output_options.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/read_bound.h"
#include "tfmatch/kernels/voxel_pair.h"  // kVoxelLaneVoxels, TFM_VOXEL_WORKGROUP
#include "tfmatch/model/synthetic.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/solvers/eigen_baseline.h"

namespace tfm::cli {
namespace {

struct BenchArgs {
  std::vector<std::string> sizes{"250x352x20", "480x720x120"};  // 1.76 M and 41.5 M voxels
  std::vector<uint32_t> tf_sizes{16, 64, 256, 1024, 4096};
  int repeats = 3;
  uint64_t eigen_max_voxels = 5'000'000;
  std::vector<uint32_t> lane_voxels;  // lane lengths to compare the read bound and assembly at
  std::string json;
};

// Best GPU time (ms) of copying every chunk of `field` into a scratch buffer, `repeats` times and
// for at least 0.3 s (warm_best_ms).
double copy_ms(Context& ctx, const DeviceField& field, int repeats) {
  Buffer scratch(ctx, field.chunk(0).size(), MemoryUsage::Device, "copy scratch");
  return warm_best_ms(repeats, [&] {
    CommandBatch batch(ctx);
    uint32_t t0 = batch.timestamp();
    for (size_t c = 0; c < field.chunk_count(); ++c) {
      batch.copy(field.chunk(c), 0, scratch, 0, field.chunk(c).size());
      batch.barrier();  // successive copies write the same scratch buffer
    }
    uint32_t t1 = batch.timestamp();
    batch.submit_and_wait();
    return batch.elapsed_ms(t0, t1);
  }, 300);
}

// Best GPU time (ms) of reading both fields with the assembly's loads (FieldPairReadKernel),
// warmed as the assembly is (warm_best_ms): timed cold, the bound ran at idle clocks and came
// out slower than the kernels it bounds. Throws when its sums differ from the CPU's (a voxel not
// read, or read twice).
double read_ms(Context& ctx, const DeviceField& ref, const DeviceField& opt, const std::array<uint32_t, 2>& expected,
               int repeats, uint64_t lane_voxels = 0) {
  const FieldPairReadKernel kernel(ctx, 0, lane_voxels);
  auto run = [&] {
    double ms = -1.0;
    if (kernel.run(ref, opt, &ms) != expected)
      throw std::runtime_error("bench: the read-bound kernel's sums differ from the CPU's on " + ctx.device_name());
    return ms;
  };
  run();  // the first run compiles the shader on lavapipe: not timed
  return warm_best_ms(repeats, run);
}

// Host-to-device rates (bytes/s) of uploading both fields, best of `repeats`: in place (host
// memory imported, Context::host_import(); 0 where the device cannot) and through staging, beside
// a plain host memcpy of the same bytes into memory already touched: the rate a staged upload's
// own host copy cannot beat.
struct UploadRates {
  double in_place = 0, staged = 0, host_memcpy = 0;
};
UploadRates upload_rates(Context& ctx, DeviceField& dref, DeviceField& dopt, const Volume& ref, const Volume& field,
                         int repeats) {
  const double bytes = double(ref.values.size() + field.values.size()) * sizeof(float);
  auto best_rate = [&](auto&& transfer) {
    double best = 1e300;
    for (int r = 0; r < repeats; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      transfer();
      best = std::min(best, seconds_since(t0));
    }
    return bytes / best;
  };
  UploadRates rates;
  std::vector<float> copy(ref.values.size() + field.values.size(), 1.0f);  // touched: no page faults timed
  rates.host_memcpy = best_rate([&] {
    std::memcpy(copy.data(), ref.values.data(), ref.values.size() * sizeof(float));
    std::memcpy(copy.data() + ref.values.size(), field.values.data(), field.values.size() * sizeof(float));
  });
  const bool import = ctx.host_import();
  auto both = [&] {
    dref.upload(ref.values);
    dopt.upload(field.values);
  };
  ctx.set_host_import(false);
  rates.staged = best_rate(both);
  ctx.set_host_import(true);
  if (ctx.host_import()) rates.in_place = best_rate(both);
  ctx.set_host_import(import);
  return rates;
}

// Largest relative difference of any entry of M, S^T b and b^T b between two systems.
double max_relative_difference(const NormalEquations& a, const NormalEquations& b) {
  double worst = 0.0;
  auto rel = [&](double x, double y) {
    if (y != 0.0) worst = std::max(worst, std::abs(x / y - 1.0));
  };
  for (uint32_t j = 0; j < b.n; ++j) rel(a.diag[j], b.diag[j]);
  for (uint32_t j = 0; j + 1 < b.n; ++j) rel(a.off[j], b.off[j]);
  for (Eigen::Index j = 0; j < b.rhs.rows(); ++j)
    for (int c = 0; c < 4; ++c) rel(a.rhs(j, c), b.rhs(j, c));
  for (int c = 0; c < 4; ++c) rel(a.btb[c], b.btb[c]);
  return worst;
}

// --lane-voxels: the read bound and the assembly (N = 64) with each lane length of the run modes'
// workgroups (ReductionOptions::lane_voxels), beside the default. Every length must give the
// default's exact sums; the fastest is what a GPU's default should be.
nlohmann::json lane_sweep(Context& ctx, const BenchArgs& a, const DeviceField& dref, const DeviceField& dopt,
                          const std::array<uint32_t, 2>& bit_sums, const FieldMapping& rm, const FieldMapping& om,
                          const Buffer& tfb) {
  GpuNormalEquations reference(ctx, 64);
  reference.add(dref, dopt, rm, om, tfb);
  const std::vector<uint64_t> expected = reference.fixed_point_slots();
  const double voxels = double(dref.voxel_count());
  std::cout << "    voxels per lane (the run modes' workgroups of " << TFM_VOXEL_WORKGROUP
            << " invocations; their default " << kVoxelLaneVoxels << "), N = 64:\n"
            << "     lane   read ms   read GB/s   assembly ms   GPU/read   path\n";
  nlohmann::json rows = nlohmann::json::array();
  for (uint32_t lane : a.lane_voxels) {
    const double read = read_ms(ctx, dref, dopt, bit_sums, a.repeats, lane);
    ReductionOptions options;
    options.lane_voxels = lane;
    GpuNormalEquations gpu(ctx, 64, options);
    gpu.add(dref, dopt, rm, om, tfb);  // first use: lavapipe compiles the shader here
    const double assemble = warm_best_ms(a.repeats, [&] {
      gpu.reset();
      return gpu.add(dref, dopt, rm, om, tfb);
    });
    if (gpu.fixed_point_slots() != expected)
      throw std::runtime_error("bench: lanes of " + std::to_string(lane) + " voxels changed the assembly's sums on " +
                               ctx.device_name());
    // Lengths only the run modes take (a CPU device's private histograms size their own lanes).
    const std::string path = reduction_mode_name(gpu.kernel().mode());
    std::cout << "    " << std::setw(5) << lane << std::fixed << std::setprecision(3) << std::setw(10) << read
              << std::setprecision(1) << std::setw(12) << voxels * 8.0 / (read * 1e-3) / 1e9 << std::setprecision(3)
              << std::setw(14) << assemble << std::setprecision(3) << std::setw(11) << read / assemble << "   "
              << path << "\n";
    rows.push_back({{"lane_voxels", lane}, {"read_ms", read}, {"read_bytes_per_s", voxels * 8.0 / (read * 1e-3)},
                    {"assemble_ms", assemble}, {"assembly_over_read_bound", read / assemble}, {"path", path},
                    {"same_sums", true}});
  }
  return rows;
}

std::string load_average() {
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) != 3) return "unknown";
  std::ostringstream os;
  os << std::fixed << std::setprecision(2) << load[0] << " " << load[1] << " " << load[2];
  return os.str();
}

int run(const BenchArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  FilePlan().output(json.file(), "--json").check();
  auto ctx = make_context();
  if (!ctx->timestamps_supported()) throw std::runtime_error("this device has no timestamps; cannot benchmark");
  const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  nlohmann::json out;
  out["device"] = ctx->device_name();
  out["cpu_threads"] = threads;
  out["load_average_before"] = load_average();
  out["runs"] = nlohmann::json::array();
  std::cout << "tfmatch bench: normal-equation assembly on " << ctx->device_name() << " (best of " << a.repeats
            << "; CPU loop on " << threads << " threads; load average " << load_average() << ")\n";
  for (const std::string& size : a.sizes) {
    const auto d = *parse_grid_size(size);  // checked as the command line was
    Volume ref = synthetic_reference(d[0], d[1], d[2]);
    Volume field = synthetic_remapped(ref);
    const uint64_t voxels = ref.voxel_count();
    const TransferFunction tf = demo_transfer_function(64);
    const FieldMapping rm = make_mapping(resolve_range(ref.values, nullptr, "ref"), 64);
    const FieldRange field_range = resolve_range(field.values, nullptr, "field");
    DeviceField dref(*ctx, ref.values, "ref"), dopt(*ctx, field.values, "field");
    Buffer tfb = upload_tf(*ctx, tf, "tf");
    // The kernel reads two float32 values per voxel; a copy of one field moves 4 bytes per voxel
    // read (and 4 written): the copy's read rate, in voxels/s of the kernel, is bytes/s / 8.
    const double copy_best = copy_ms(*ctx, dref, a.repeats);
    const double copy_bytes_per_s = double(voxels) * 4.0 / (copy_best * 1e-3);
    const double bound_voxels_per_s = copy_bytes_per_s / 8.0;
    // The read bound: both fields read as the assembly reads them, 8 bytes per voxel.
    const std::array<uint32_t, 2> bit_sums = field_pair_bit_sums(ref.values, field.values);
    const double read_best = read_ms(*ctx, dref, dopt, bit_sums, a.repeats);
    const double read_voxels_per_s = double(voxels) / (read_best * 1e-3);
    const UploadRates up = upload_rates(*ctx, dref, dopt, ref, field, a.repeats);
    std::cout << "\n  " << size << " (" << std::setprecision(3) << double(voxels) / 1e6 << " M voxels); copy bound "
              << std::fixed << std::setprecision(0) << bound_voxels_per_s / 1e6 << " M voxels/s ("
              << std::setprecision(2) << copy_bytes_per_s / 1e9 << " GB/s copy); read bound " << std::setprecision(0)
              << read_voxels_per_s / 1e6 << " M voxels/s (" << std::setprecision(2) << read_voxels_per_s * 8.0 / 1e9
              << " GB/s read)\n"
              << "  upload of both fields: in place " << std::setprecision(2) << up.in_place / 1e9 << " GB/s, staged "
              << up.staged / 1e9 << " GB/s; host memcpy " << up.host_memcpy / 1e9 << " GB/s\n"
              << "    N      GPU ms   M vox/s   CPU loop ms   M vox/s   GPU/CPU   GPU/copy   GPU/read"
                 "   max rel. diff   path\n";
    nlohmann::json entry{{"dims", size}, {"voxels", voxels}, {"copy_ms", copy_best},
                         {"copy_bytes_per_s", copy_bytes_per_s}, {"copy_bound_voxels_per_s", bound_voxels_per_s},
                         {"read_ms", read_best}, {"read_bound_voxels_per_s", read_voxels_per_s},
                         {"upload_in_place_bytes_per_s", up.in_place}, {"upload_staged_bytes_per_s", up.staged},
                         {"host_memcpy_bytes_per_s", up.host_memcpy},
                         {"tf_sizes", nlohmann::json::array()}};
    for (uint32_t n : a.tf_sizes) {
      const FieldMapping om = make_mapping(field_range, n);
      GpuNormalEquations gpu(*ctx, n);
      gpu.add(dref, dopt, rm, om, tfb);  // first use: lavapipe compiles the shader here
      // GPU and CPU repeats alternate, so that both see the same machine (a shared machine's
      // speed drifts over seconds) and the best of each is from the same stretch of time.
      double gpu_best = 1e300, cpu_best = 1e300;
      NormalEquations cpu(n);
      for (int r = 0; r < a.repeats; ++r) {
        gpu_best = std::min(gpu_best, warm_best_ms(1, [&] {
                              gpu.reset();
                              return gpu.add(dref, dopt, rm, om, tfb);
                            }));
        const auto t0 = std::chrono::steady_clock::now();
        cpu = assemble_normal_equations_cpu_threaded(ref.values, field.values, rm, om, tf, threads);
        cpu_best = std::min(cpu_best, seconds_since(t0) * 1e3);
      }
      const double diff = max_relative_difference(gpu.result(), cpu);
      const double gpu_rate = double(voxels) / (gpu_best * 1e-3), cpu_rate = double(voxels) / (cpu_best * 1e-3);
      const std::string path = std::string(reduction_mode_name(gpu.kernel().mode())) +
                               (gpu.kernel().int64_atomics() ? ", 64-bit atomics" : ", 32-bit atomics");
      std::cout << "    " << std::left << std::setw(5) << n << std::right << std::fixed << std::setprecision(1)
                << std::setw(9) << gpu_best << std::setw(10) << gpu_rate / 1e6 << std::setw(14) << cpu_best
                << std::setw(10) << cpu_rate / 1e6 << std::setprecision(2) << std::setw(10) << cpu_best / gpu_best
                << std::setprecision(3) << std::setw(11) << gpu_rate / bound_voxels_per_s << std::setw(11)
                << gpu_rate / read_voxels_per_s << std::scientific
                << std::setprecision(1) << std::setw(16) << diff << std::defaultfloat << "   " << path << "\n";
      entry["tf_sizes"].push_back({{"n", n},
                                   {"gpu_assemble_ms", gpu_best},
                                   {"gpu_voxels_per_s", gpu_rate},
                                   {"cpu_loop_ms", cpu_best},
                                   {"cpu_loop_voxels_per_s", cpu_rate},
                                   {"gpu_over_cpu_loop", cpu_best / gpu_best},
                                   {"gpu_over_copy_bound", gpu_rate / bound_voxels_per_s},
                                   {"gpu_over_read_bound", gpu_rate / read_voxels_per_s},
                                   {"max_relative_difference", diff},
                                   {"path", path}});
    }
    if (!a.lane_voxels.empty())
      entry["lane_voxels"] = lane_sweep(*ctx, a, dref, dopt, bit_sums, rm, make_mapping(field_range, 64), tfb);
    if (voxels <= a.eigen_max_voxels) {
      // The paper's CPU baseline: explicit sparse A (CSR), then A^T A and A^T b with Eigen (N = 64).
      const FieldMapping om = make_mapping(field_range, 64);
      auto t0 = std::chrono::steady_clock::now();
      ExplicitSystem sys = build_explicit_system(ref.values, field.values, rm, om, tf);
      const double build_s = seconds_since(t0);
      t0 = std::chrono::steady_clock::now();
      ExplicitNormalEquations ne = explicit_normal_equations(sys);
      const double eigen_s = build_s + seconds_since(t0);
      GpuNormalEquations gpu(*ctx, 64);
      const double gpu_ms = gpu.add(dref, dopt, rm, om, tfb);
      entry["cpu_eigen_s"] = eigen_s;
      entry["gpu_over_eigen_n64"] = eigen_s * 1e3 / gpu_ms;
      std::cout << "    Eigen (paper, N = 64): " << std::fixed << std::setprecision(1) << eigen_s * 1e3 << " ms, "
                << double(voxels) / eigen_s / 1e6 << " M voxels/s; GPU/Eigen " << eigen_s * 1e3 / gpu_ms
                << "; max rel. diff " << std::scientific << std::setprecision(1)
                << max_relative_difference(gpu.result(), to_tridiagonal(ne, 64)) << std::defaultfloat << "\n";
    } else {
      std::cout << "    Eigen (paper): skipped (more than --eigen-max-voxels)\n";
    }
    out["runs"].push_back(entry);
  }
  out["load_average_after"] = load_average();
  std::cout << "\n  GPU/CPU > 1: the assembly is faster than the CPU loop; GPU/copy, GPU/read: fractions of the copy\n"
               "  speed and of the speed at the assembly's own loads (read bound).\n"
            << "  load average after: " << load_average() << "\n";
  json.write(out);
  return 0;
}

CommandRegistration reg(80, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand(
      "bench", "Benchmark normal-equation assembly against a multi-threaded CPU loop, copy speed and Eigen");
  sub->add_option("--sizes", args->sizes, "Grids XxYxZ, comma separated (default: the paper's 1.76 M and 41.5 M voxels)")
      ->delimiter(',')
      ->check(grid_size_check())
      ->capture_default_str();
  sub->add_option("--tf-sizes", args->tf_sizes, "TF entries to assemble for, comma separated")
      ->delimiter(',')
      ->check(CLI::Range(2u, 1u << 20))
      ->capture_default_str();
  sub->add_option("--repeats", args->repeats, "Repetitions (best is reported)")->check(CLI::Range(1, 100))
      ->capture_default_str();
  sub->add_option("--eigen-max-voxels", args->eigen_max_voxels, "Skip the Eigen baseline above this size")
      ->capture_default_str();
  sub->add_option("--lane-voxels", args->lane_voxels,
                  "Also time the read bound and the assembly (N = 64) with lanes of these many voxels, comma "
                  "separated (the GPU kernels' workgroup count; each must give the default's exact sums; at most "
                  "131072: lavapipe ends a lane's loops after 65535 iterations)")
      ->delimiter(',')
      ->check(CLI::Range(4u, 1u << 17));
  add_json_option(sub, args->json, "the numbers");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
