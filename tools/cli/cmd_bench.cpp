// `tfmatch bench`: normal-equation assembly throughput on the paper's data sizes, beside what
// bounds it — this device's buffer-copy speed for the bytes the kernel reads — and the paper's
// CPU baseline (explicit sparse A with Eigen, A^T A and A^T b), as ratios measured in one run.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "normal_equations_cpu.h"
#include "atomic_file.h"
#include "cli.h"
#include "commands.h"
#include "output_check.h"
#include "output_options.h"
#include "eigen_baseline.h"
#include "gpu_voxel_ops.h"
#include "synthetic.h"

namespace tfm::cli {
namespace {

struct BenchArgs {
  std::vector<std::string> sizes{"250x352x20", "480x720x120"};  // 1.76 M and 41.5 M voxels
  int repeats = 5;
  uint64_t cpu_max_voxels = 50'000'000;
  std::string json;
};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::array<uint64_t, 3> parse_dims(const std::string& s) {
  std::array<uint64_t, 3> d{};
  char x1 = 0, x2 = 0;
  std::istringstream in(s);
  if (!(in >> d[0] >> x1 >> d[1] >> x2 >> d[2]) || x1 != 'x' || x2 != 'x' || !d[0] || !d[1] || !d[2])
    throw std::runtime_error("--sizes: expected XxYxZ, got '" + s + "'");
  return d;
}

// Best GPU time (ms) of copying every chunk of `field` into a scratch buffer.
double copy_ms(Context& ctx, const DeviceField& field, int repeats) {
  Buffer scratch(ctx, field.chunk(0).size(), MemoryUsage::Device, "copy scratch");
  double best = 1e300;
  for (int r = 0; r < repeats; ++r) {
    CommandBatch batch(ctx);
    uint32_t t0 = batch.timestamp();
    for (size_t c = 0; c < field.chunk_count(); ++c) {
      batch.copy(field.chunk(c), 0, scratch, 0, field.chunk(c).size());
      batch.barrier();  // successive copies write the same scratch buffer
    }
    uint32_t t1 = batch.timestamp();
    batch.submit_and_wait();
    best = std::min(best, batch.elapsed_ms(t0, t1));
  }
  return best;
}

int run(const BenchArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  FilePlan().output(json.file(), "--json").check();
  auto ctx = make_context();
  if (!ctx->timestamps_supported()) throw std::runtime_error("this device has no timestamps; cannot benchmark");
  nlohmann::json out;
  out["device"] = ctx->device_name();
  out["runs"] = nlohmann::json::array();
  std::cout << "tfmatch bench: normal-equation assembly on " << ctx->device_name() << " (best of " << a.repeats
            << "; TF 64 entries)\n";
  for (const std::string& size : a.sizes) {
    const auto d = parse_dims(size);
    Volume ref = synthetic_reference(d[0], d[1], d[2]);
    Volume field = synthetic_remapped(ref);
    const uint64_t voxels = ref.voxel_count();
    TransferFunction tf = demo_transfer_function(64);
    FieldMapping rm = make_mapping(resolve_range(ref.values, nullptr, "ref"), 64);
    FieldMapping om = make_mapping(resolve_range(field.values, nullptr, "field"), 64);

    DeviceField dref(*ctx, ref.values, "ref"), dopt(*ctx, field.values, "field");
    Buffer tfb = upload_tf(*ctx, tf, "tf");
    // The kernel reads two float32 values per voxel; a copy of one field moves 4 bytes per voxel
    // read (and 4 written): the copy's read rate, in voxels/s of the kernel, is bytes/s / 8.
    const double copy_best = copy_ms(*ctx, dref, a.repeats);
    const double copy_bytes_per_s = double(voxels) * 4.0 / (copy_best * 1e-3);
    const double bound_voxels_per_s = copy_bytes_per_s / 8.0;

    GpuNormalEquations gpu(*ctx, 64);
    double assemble_best = 1e300;
    for (int r = 0; r < a.repeats; ++r) {
      gpu.reset();
      assemble_best = std::min(assemble_best, gpu.add(dref, dopt, rm, om, tfb));
    }
    NormalEquations g = gpu.result();
    const double gpu_voxels_per_s = double(voxels) / (assemble_best * 1e-3);

    nlohmann::json entry{{"dims", size}, {"voxels", voxels}, {"gpu_assemble_ms", assemble_best},
                       {"gpu_voxels_per_s", gpu_voxels_per_s}, {"copy_ms", copy_best},
                       {"copy_bytes_per_s", copy_bytes_per_s}, {"copy_bound_voxels_per_s", bound_voxels_per_s}};
    std::cout << "\n  " << size << " (" << std::setprecision(3) << double(voxels) / 1e6 << " M voxels)\n"
              << std::fixed << std::setprecision(2)
              << "    GPU assembly          " << std::setw(9) << assemble_best << " ms  " << std::setw(9)
              << gpu_voxels_per_s / 1e6 << " M voxels/s\n"
              << "    copy-speed bound      " << std::setw(9) << copy_best << " ms  " << std::setw(9)
              << bound_voxels_per_s / 1e6 << " M voxels/s  (" << copy_bytes_per_s / 1e9 << " GB/s copy)\n"
              << "    assembly / bound      " << std::setw(9) << std::defaultfloat << std::setprecision(3)
              << gpu_voxels_per_s / bound_voxels_per_s << std::fixed << std::setprecision(2) << "\n";

    // The straightforward CPU method, single thread, in double: our reference.
    auto t0 = std::chrono::steady_clock::now();
    NormalEquations cpu_direct = assemble_normal_equations_cpu(ref.values, field.values, rm, om, tf);
    const double direct_s = seconds_since(t0);
    entry["cpu_direct_s"] = direct_s;
    std::cout << "    CPU direct (1 thread) " << std::setw(9) << direct_s * 1e3 << " ms  " << std::setw(9)
              << double(voxels) / direct_s / 1e6 << " M voxels/s   GPU/CPU " << direct_s * 1e3 / assemble_best
              << "\n";
    double max_rel = 0;
    for (uint32_t j = 0; j < 64; ++j)
      if (cpu_direct.diag[j] > 0) max_rel = std::max(max_rel, std::abs(g.diag[j] / cpu_direct.diag[j] - 1));
    entry["max_relative_difference_diag"] = max_rel;

    if (voxels <= a.cpu_max_voxels) {
      // The paper's CPU baseline: explicit sparse A (CSR), then A^T A and A^T b with Eigen.
      t0 = std::chrono::steady_clock::now();
      ExplicitSystem sys = build_explicit_system(ref.values, field.values, rm, om, tf);
      const double build_s = seconds_since(t0);
      t0 = std::chrono::steady_clock::now();
      ExplicitNormalEquations ne = explicit_normal_equations(sys);
      const double product_s = seconds_since(t0);
      const double eigen_s = build_s + product_s;
      entry["cpu_eigen_build_s"] = build_s;
      entry["cpu_eigen_products_s"] = product_s;
      entry["gpu_speedup_over_eigen"] = eigen_s * 1e3 / assemble_best;
      NormalEquations e = to_tridiagonal(ne, 64);
      for (uint32_t j = 0; j < 64; ++j)
        if (e.diag[j] > 0) max_rel = std::max(max_rel, std::abs(g.diag[j] / e.diag[j] - 1));
      std::cout << "    CPU Eigen (paper)     " << std::setw(9) << eigen_s * 1e3 << " ms  " << std::setw(9)
                << double(voxels) / eigen_s / 1e6 << " M voxels/s   GPU/Eigen " << eigen_s * 1e3 / assemble_best
                << "  (build A " << build_s * 1e3 << " ms, A^T A + A^T b " << product_s * 1e3 << " ms)\n";
    } else {
      std::cout << "    CPU Eigen (paper)     skipped (more than --cpu-max-voxels)\n";
    }
    std::cout << "    max relative difference of diag(M), GPU vs CPU: " << std::scientific << std::setprecision(2)
              << max_rel << std::defaultfloat << "\n";
    out["runs"].push_back(entry);
  }
  json.write(out);
  return 0;
}

CommandRegistration reg(80, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand("bench", "Benchmark normal-equation assembly against copy speed and the Eigen CPU path");
  sub->add_option("--sizes", args->sizes, "Grids XxYxZ (default: the paper's 1.76 M and 41.5 M voxels)")
      ->capture_default_str();
  sub->add_option("--repeats", args->repeats, "Repetitions (best is reported)")->check(CLI::Range(1, 100))
      ->capture_default_str();
  sub->add_option("--cpu-max-voxels", args->cpu_max_voxels, "Skip the Eigen baseline above this size")
      ->capture_default_str();
  add_json_option(sub, args->json, "the numbers");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
