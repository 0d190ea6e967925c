// `tfmatch bench-solve`: the normal-equations solve and cond(M) against the TF size N on one field
// pair, up to the largest N the command line accepts (65536): assembly and host-solve time, the
// rank the data give (unreferenced and dependent entries), cond(M), voxel RMSE and the process's
// peak resident memory, so that O(N) time and memory can be seen on real data.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include <sys/resource.h>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm::cli {
namespace {

struct BenchSolveArgs {
  InputArgs input;
  std::vector<uint32_t> sizes{64, 1024, 4096, 16384, 65536};
  std::string json;
};

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

uint64_t peak_resident_bytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return uint64_t(u.ru_maxrss) * 1024;  // kB on Linux
}

int run(const BenchSolveArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  FilePlan()
      .input_spec(a.input.ref, "--ref")
      .input_spec(a.input.field, "--field")
      .input_spec(a.input.ref_tf, "--ref-tf")
      .output(json.file(), "--json")
      .check();
  LoadedInputs in;
  if (a.input.ref.empty()) {
    // Without inputs: the demo pair at 128^3.
    reject_input_flags(a.input, "without --ref bench-solve runs the demo's 128^3 pair");
    in.ref = synthetic_reference(128, 128, 128);
    in.field = synthetic_remapped(in.ref);
    in.request.ref_tf = demo_transfer_function(64);
  } else {
    if (a.input.field.empty() || a.input.ref_tf.empty()) throw std::runtime_error("give --ref, --field and --ref-tf together");
    load_inputs(a.input, in);
  }
  require_same_grid(in.ref, in.field);
  const TransferFunction& ref_tf = in.request.ref_tf;
  const FieldRange* ref_user = in.request.ref_range ? &*in.request.ref_range : (ref_tf.range ? &*ref_tf.range : nullptr);
  const FieldRange ref_range = resolve_range(in.ref.values, ref_user, in.ref.name);
  const FieldRange field_range =
      resolve_range(in.field.values, in.request.field_range ? &*in.request.field_range : nullptr, in.field.name);
  auto ctx = make_context();
  DeviceField ref(*ctx, in.ref.values, "reference field"), field(*ctx, in.field.values, "second field");
  Buffer tf = upload_tf(*ctx, ref_tf, "reference TF");
  const FieldMapping ref_map = make_mapping(ref_range, uint32_t(ref_tf.size()));

  std::cout << "tfmatch bench-solve: " << in.field.name << " against " << in.ref.name << " (" << in.ref.voxel_count()
            << " voxels) on " << ctx->device_name() << "\n";
  std::printf("%8s %12s %10s %10s %8s %8s %10s %12s %10s\n", "N", "assemble ms", "solve ms", "cond ms", "unref", "dep",
              "cond", "voxel RMSE", "peak RSS");
  nlohmann::json rows = nlohmann::json::array();
  for (uint32_t n : a.sizes) {
    if (n < 2 || n > (1u << 16)) throw std::runtime_error("--tf-sizes: each N must be in 2..65536, got " + std::to_string(n));
    auto t0 = std::chrono::steady_clock::now();
    GpuNormalEquations gpu(*ctx, n);
    gpu.add(ref, field, ref_map, make_mapping(field_range, n), tf);
    const NormalEquations eq = gpu.result();
    const double assemble_ms = ms_since(t0);
    t0 = std::chrono::steady_clock::now();
    const SolveResult solved = solve_normal_equations(eq);
    const double solve_ms = ms_since(t0);
    t0 = std::chrono::steady_clock::now();
    tridiagonal_extreme_eigenvalues(regularized_matrix(eq, {}));
    const double cond_ms = ms_since(t0);
    Eigen::Matrix<double, Eigen::Dynamic, 4> x(n, 4);
    for (uint32_t j = 0; j < n; ++j)
      for (int c = 0; c < 4; ++c) x(j, c) = solved.tf.rgba[j][size_t(c)];
    const double rmse = std::sqrt(eq.residual_squared(x) / (4.0 * double(eq.voxels)));
    const uint64_t peak = peak_resident_bytes();
    std::printf("%8u %12.1f %10.2f %10.2f %8u %8u %10.3g %12.5f %10s\n", n, assemble_ms, solve_ms, cond_ms,
                solved.unreferenced_entries, solved.dependent_entries, solved.cond, rmse, format_bytes(peak).c_str());
    std::fflush(stdout);
    rows.push_back({{"tf_size", n},
                    {"assemble_ms", assemble_ms},
                    {"solve_ms", solve_ms},
                    {"cond_ms", cond_ms},
                    {"unreferenced_entries", solved.unreferenced_entries},
                    {"dependent_entries", solved.dependent_entries},
                    {"factorization", solved.factorization},
                    {"cond", std::isfinite(solved.cond) ? nlohmann::json(solved.cond) : nlohmann::json("inf")},
                    {"voxel_rmse", rmse},
                    {"peak_resident_bytes", peak}});
  }
  OutputBatch outputs;
  json.write({{"device", ctx->device_name()}, {"runs", rows}});
  outputs.commit();
  return 0;
}

CommandRegistration reg(83, [](CLI::App& app) {
  auto args = std::make_shared<BenchSolveArgs>();
  auto* sub = app.add_subcommand("bench-solve", "Benchmark the normal-equations solve and cond(M) against the TF size "
                                                "(time, rank, peak memory)");
  add_input_options(sub, args->input, false);
  remove_options(sub, {"--tf-size"});  // --tf-sizes gives the sizes
  sub->add_option("--tf-sizes", args->sizes, "TF sizes N to run, comma-separated (2..65536)")->delimiter(',')
      ->capture_default_str();
  add_json_option(sub, args->json, "the numbers");
  sub->footer("Without --ref/--field/--ref-tf: tfmatch demo's pair at 128^3. Peak RSS is the process's, cumulative.");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
