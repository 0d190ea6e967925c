// `tfmatch bench-diffdvr`: DiffDVR's time per iteration (the field's forward pass and the
// backward pass, reference images from a pool rendered once) and peak buffer memory beside a
// forward-only render of the same views, at two step sizes (so twice the samples per ray); with
// --cube, the paper's synthetic cube table: image metrics of the voxel solvers against DiffDVR's.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <numeric>
#include <random>

#include "cli.h"
#include "output_options.h"
#include "render_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/cameras.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/model/synthetic_cube.h"
#include "tfmatch/report/metrics.h"
#include "tfmatch/solvers/optimize.h"
#include "tfmatch/solvers/solver_diffdvr.h"

namespace tfm::cli {
namespace {

struct BenchArgs {
  uint64_t size = 128;
  uint32_t image = 512;
  uint32_t views = 8;
  uint32_t repeat = 3;
  std::vector<double> steps{0.5, 0.25};
  bool cube = false;
  bool cube_only = false;
  uint64_t cube_size = 64;
  double cube_opacity = 0.4;  // the interior shows faintly: ~37 dB for the reference TF, as in the paper
  uint32_t cube_image = 128;
  uint32_t iterations = 200;
  std::string json;
  RenderSettings settings;
};

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

double mib(uint64_t bytes) { return double(bytes) / (1024.0 * 1024.0); }

// One row: a forward-only render of `views` cameras, then DiffDVR iterations on new cameras.
nlohmann::json bench_step(Context& ctx, const BenchArgs& a, double step, const DeviceField& ref, const DeviceField& opt,
                          const VolumeGeometry& geo, const FieldMapping& ref_map, const FieldMapping& opt_map,
                          const Buffer& ref_tf, const Buffer& opt_tf, const TransferFunction& opt_tf_host) {
  RenderSettings s = a.settings;
  s.width = s.height = a.image;
  s.step_voxels = step;
  const MarchConstants march = march_constants(s, geo);
  RandomCameras random(1, s.camera);
  const uint64_t pixels = uint64_t(s.width) * s.height * a.views;

  // Forward only: the renderer's kernel, all views in one dispatch.
  ctx.reset_peak_buffer_bytes();
  uint64_t base = ctx.buffer_bytes();
  double forward_only_ms = 1e300, forward_only_wall = 1e300;
  uint64_t samples = 0, rays_hit = 0, forward_only_peak = 0;
  {
    RenderImageKernel kernel(ctx, uint32_t(opt.chunk_count()));
    std::vector<gpu::RenderView> records;
    for (const OrbitCamera& c : random.next(a.views)) records.push_back(make_render_view(orbit_frame(c, geo, s.width, s.height)));
    Buffer views = make_buffer<gpu::RenderView>(ctx, std::span<const gpu::RenderView>(records), "bench cameras");
    Buffer image(ctx, pixels * 16, MemoryUsage::Device, "bench image");
    Buffer stop(ctx, pixels * 4, MemoryUsage::Device, "bench stop");
    const gpu::RenderPush push = make_render_push(geo, march, opt_map, opt, s.width, s.height, a.views);
    for (uint32_t r = 0; r <= a.repeat; ++r) {  // the first is a warm-up
      const auto t0 = std::chrono::steady_clock::now();
      CommandBatch batch(ctx);
      const uint32_t q0 = batch.timestamp();
      kernel.record(batch, opt, opt_tf, views, push, image, stop, 0, s.height);
      const uint32_t q1 = batch.timestamp();
      batch.submit_and_wait();
      if (r == 0) continue;
      const double ms = batch.elapsed_ms(q0, q1);
      forward_only_wall = std::min(forward_only_wall, ms_since(t0));
      forward_only_ms = std::min(forward_only_ms, ms >= 0 ? ms : ms_since(t0));
    }
    forward_only_peak = ctx.peak_buffer_bytes() - base;  // before the readback's staging buffer
    std::vector<uint32_t> k_stop(pixels);
    readback(ctx, stop, k_stop.data(), pixels * 4);
    for (uint32_t k : k_stop) samples += k, rays_hit += k > 0;
  }

  // DiffDVR iterations as the solver runs them: a pool of 4 x views cameras whose reference
  // images are rendered once, then per iteration the field's forward pass and the backward pass
  // for `views` of them (a seeded choice).
  ctx.reset_peak_buffer_bytes();
  base = ctx.buffer_bytes();
  double fwd = 1e300, bwd = 1e300, wall = 1e300, pool_ms = 0.0;
  {
    DiffDvrGradient gradient(ctx, ref, opt, geo, ref_map, ref_tf, opt_map, s, ImageLoss::L2);
    const auto tp = std::chrono::steady_clock::now();
    gradient.set_view_pool(random.next(4 * a.views));
    pool_ms = ms_since(tp);
    std::vector<uint32_t> order(gradient.pool_size());
    std::iota(order.begin(), order.end(), 0u);
    std::mt19937_64 choose(1);
    for (uint32_t r = 0; r <= a.repeat; ++r) {
      for (uint32_t i = 0; i < a.views; ++i) std::swap(order[i], order[i + choose() % (order.size() - i)]);
      const auto t0 = std::chrono::steady_clock::now();
      const ImageLossGradient g = gradient.evaluate_pooled(opt_tf_host, std::span<const uint32_t>(order.data(), a.views));
      if (r == 0) continue;
      wall = std::min(wall, ms_since(t0));
      fwd = std::min(fwd, g.forward_gpu_ms >= 0 ? g.forward_gpu_ms : ms_since(t0));
      bwd = std::min(bwd, g.backward_gpu_ms >= 0 ? g.backward_gpu_ms : 0.0);
    }
  }
  const uint64_t iteration_peak = ctx.peak_buffer_bytes() - base;
  const double steps_per_ray = rays_hit ? double(samples) / double(rays_hit) : 0.0;
  std::printf("%5.2f %8.1f %9.1f %10.1f %6.2f %9.1f %10.1f %6.2f %10.1f %9.1f %9.1f %9.1f\n", step, steps_per_ray,
              forward_only_ms, fwd + bwd, (fwd + bwd) / forward_only_ms, fwd, bwd, bwd / fwd,
              double(samples) / (forward_only_ms * 1e3), mib(forward_only_peak), mib(iteration_peak), pool_ms);
  std::fflush(stdout);
  return {{"step_voxels", step},
          {"steps_per_ray", steps_per_ray},
          {"max_steps", march.max_steps},
          {"rays_hit", rays_hit},
          {"forward_only_gpu_ms", forward_only_ms},
          {"iteration_gpu_ms", fwd + bwd},
          {"iteration_over_forward_only", (fwd + bwd) / forward_only_ms},
          {"iteration_wall_ms", wall},
          {"forward_pass_gpu_ms", fwd},
          {"backward_gpu_ms", bwd},
          {"backward_over_forward", bwd / fwd},
          {"reference_pool_views", 4 * a.views},
          {"reference_pool_wall_ms", pool_ms},
          {"forward_only_peak_bytes", forward_only_peak},
          {"iteration_peak_bytes", iteration_peak},
          {"iteration_bytes_per_ray", double(iteration_peak) / double(pixels)}};
}

nlohmann::json bench_iterations(Context& ctx, const BenchArgs& a) {
  if (!globals().quiet) std::cerr << "generating the " << a.size << "^3 demo pair...\n";
  const Volume ref = synthetic_reference(a.size, a.size, a.size), field = synthetic_remapped(ref);
  const TransferFunction tf = demo_transfer_function(64);
  const FieldRange field_range = resolve_range(field.values, nullptr, "field");
  const VolumeGeometry geo = VolumeGeometry::from(ref.dims, ref.spacing, a.settings.z_scale);
  DeviceField ref_dev(ctx, ref.values, "bench reference"), opt_dev(ctx, field.values, "bench field");
  Buffer tf_buf = upload_tf(ctx, tf, "bench TF");
  const FieldMapping ref_map = make_mapping({0, 1}, 64), opt_map = make_mapping(field_range, 64);
  std::printf("bench-diffdvr on %s: %llu^3 demo pair, %u views of %ux%u per iteration, demo TF (64 entries),\n"
              "  opacity scale %g, termination at opacity %g; best of %u (GPU timestamps). An iteration renders\n"
              "  the field (1 forward pass) and runs the backward pass against reference images taken from a\n"
              "  pool of 4 x views cameras rendered once (pool ms, wall time); forward-only is one render of the\n"
              "  field from the same number of views with the renderer's kernel. Backward pass: %s.\n\n",
              ctx.device_name().c_str(), static_cast<unsigned long long>(a.size), a.views, a.image, a.image,
              a.settings.opacity_scale, a.settings.termination_opacity, a.repeat,
              reduction_mode_name(DiffDvrBackwardKernel::choose(ctx, 64)));
  std::printf("%5s %8s %9s %10s %6s %9s %10s %6s %10s %9s %9s %9s\n", "step", "steps/", "fwd-only", "iteration",
              "iter/", "forward", "backward", "bwd/", "fwd-only", "peak MiB", "peak MiB", "pool");
  std::printf("%5s %8s %9s %10s %6s %9s %10s %6s %10s %9s %9s %9s\n", "voxel", "ray", "ms", "ms", "fwd", "ms", "ms",
              "fwd", "Msamples/s", "fwd-only", "iteration", "ms");
  nlohmann::json rows = nlohmann::json::array();
  for (double step : a.steps) rows.push_back(bench_step(ctx, a, step, ref_dev, opt_dev, geo, ref_map, opt_map, tf_buf, tf_buf, tf));
  return rows;
}

// The paper's Table 3: the second field with the reference TF ("original"), the voxel solvers'
// TFs, and DiffDVR's from both starting points, measured on one rendering from settings.camera.
nlohmann::json bench_cube(Context& ctx, const BenchArgs& a) {
  const Volume ref = cube_halves(a.cube_size), field = cube_with_inner_cube(a.cube_size, 0.5);
  const TransferFunction tf = blue_to_red_tf(64, a.cube_opacity);
  const RenderSettings& s = a.settings;
  const Image target = composite_over(render_volume(ctx, ref, tf, {0, 1}, s), s.background);
  std::printf("\ncube case: %llu^3, inner cube of half the side with flipped values, blue-to-red TF (64 entries,\n"
              "  opacity %g); metrics on a %ux%u rendering from azimuth %g elevation %g. DiffDVR: %u iterations,\n"
              "  %u random views of %ux%u each, l2, default Adam settings.\n\n",
              static_cast<unsigned long long>(a.cube_size), a.cube_opacity, s.width, s.height, s.camera.azimuth_deg,
              s.camera.elevation_deg, a.iterations, a.views, a.cube_image, a.cube_image);
  std::printf("%-34s %8s %8s %8s %10s\n", "TF for the second field", "RMSE", "PSNR dB", "SSIM", "time s");
  nlohmann::json rows = nlohmann::json::array();
  auto row = [&](const std::string& name, const TransferFunction& t, double seconds) {
    const ImageMetrics m = compare_images(target, composite_over(render_volume(ctx, field, t, {0, 1}, s), s.background));
    std::printf("%-34s %8.3f %8.2f %8.4f %10.2f\n", name.c_str(), m.rmse, m.psnr, m.ssim, seconds);
    std::fflush(stdout);
    rows.push_back({{"tf", name}, {"metrics", m.to_json()}, {"seconds", seconds}});
  };
  row("reference TF (original)", tf, 0.0);
  struct Run {
    std::string name, solver;
    std::map<std::string, std::string> extra;
  };
  std::vector<Run> runs = {{"normal-equations", "normal-equations", {}}};
  if (find_solver("cgls")) runs.push_back({"cgls", "cgls", {}});
  runs.push_back({"normal-equations, visibility weights", "normal-equations", {{"weights", "visibility"}}});
  runs.push_back({"qp, visibility weights", "qp", {{"weights", "visibility"}}});
  if (find_solver("cgls")) runs.push_back({"cgls, visibility weights", "cgls", {{"weights", "visibility"}}});
  const std::map<std::string, std::string> dd = {{"iterations", std::to_string(a.iterations)},
                                                 {"views-per-iteration", std::to_string(a.views)},
                                                 {"image-size", std::to_string(a.cube_image)}};
  runs.push_back({"diffdvr l2 (init reference)", "diffdvr", dd});
  auto from_ne = dd;
  from_ne["init"] = "normal-equations";
  runs.push_back({"diffdvr l2 (init normal-equations)", "diffdvr", from_ne});
  for (const Run& r : runs) {
    OptimizeRequest req;
    req.ref = &ref;
    req.field = &field;
    req.ref_tf = tf;
    req.tf_size = 64;
    req.solver = r.solver;
    req.settings.extra = r.extra;
    req.settings.render = s;
    const auto t0 = std::chrono::steady_clock::now();
    const OptimizeResult result = run_optimize(ctx, req);
    row(r.name, result.tf, ms_since(t0) * 1e-3);
  }
  return rows;
}

int run(const BenchArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  set_progress_enabled(!globals().quiet);
  FilePlan().output(json.file(), "--json").check();
  validate(a.settings);
  auto ctx = make_context();
  nlohmann::json j{{"device", ctx->device_name()}};
  if (!a.cube_only) {
    j["iterations"] = bench_iterations(*ctx, a);
    // How the backward pass sums its gradients on this device, as the table's header says.
    j["backward_reduction"] = reduction_mode_name(DiffDvrBackwardKernel::choose(*ctx, 64));
  }
  if (a.cube || a.cube_only) j["cube"] = bench_cube(*ctx, a);
  json.write(j);
  return 0;
}

CommandRegistration reg(92, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand("bench-diffdvr", "Benchmark DiffDVR iterations against forward-only rendering; "
                                 "--cube adds the synthetic cube comparison with the voxel solvers");
  sub->add_option("--size", args->size, "Volume size per axis")->check(CLI::Range(8, 1024))->capture_default_str();
  sub->add_option("--image-size", args->image, "Image width and height")->check(CLI::Range(8u, 8192u))
      ->capture_default_str();
  sub->add_option("--views", args->views, "Views per iteration")->check(CLI::Range(1u, 256u))->capture_default_str();
  sub->add_option("--repeat", args->repeat, "Timed runs per row (the best counts)")->check(CLI::Range(1u, 100u))
      ->capture_default_str();
  sub->add_option("--steps", args->steps, "Step sizes in voxels, comma separated")->delimiter(',')
      ->check(CLI::Range(0.05, 8.0))->capture_default_str();
  sub->add_flag("--cube", args->cube, "Also run the synthetic cube case (voxel solvers vs DiffDVR)");
  sub->add_flag("--cube-only", args->cube_only, "Run only the synthetic cube case");
  sub->add_option("--cube-size", args->cube_size, "Cube case: grid size per axis")->check(CLI::Range(8, 512))
      ->capture_default_str();
  sub->add_option("--cube-opacity", args->cube_opacity, "Cube case: opacity of the blue-to-red TF")
      ->check(CLI::Range(0.0, 1.0))->capture_default_str();
  sub->add_option("--cube-image-size", args->cube_image, "Cube case: DiffDVR's training image size")
      ->check(CLI::Range(8u, 4096u))->capture_default_str();
  sub->add_option("--iterations", args->iterations, "Cube case: DiffDVR iterations")->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  add_json_option(sub, args->json, "the results");
  add_render_options(sub, args->settings);
  remove_options(sub, {"--step"});  // --steps gives the step sizes
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
