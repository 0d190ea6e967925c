// `tfmatch bench-render`: GPU renderer throughput (samples per second) for 512x512 and
// 1024x1024 images of a synthetic 256^3 volume, beside the double-precision CPU reference's.
#include <chrono>
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "output_options.h"
#include "render_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/reference/cpu_renderer.h"

namespace tfm::cli {
namespace {

struct BenchArgs {
  uint64_t size = 256;
  std::vector<uint32_t> images{512, 1024};
  uint32_t repeat = 3;
  uint32_t cpu_rows = 8;
  std::string json;
  RenderSettings settings;
};

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int run(const BenchArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  set_progress_enabled(!globals().quiet);
  FilePlan().output(json.file(), "--json").check();
  auto ctx = make_context();
  const bool quiet = globals().quiet;
  if (!quiet) std::cerr << "generating the " << a.size << "^3 synthetic volume...\n";
  Volume volume = synthetic_reference(a.size, a.size, a.size);
  const TransferFunction tf = demo_transfer_function(64);
  const FieldRange range{0.0, 1.0};
  const VolumeGeometry geometry = VolumeGeometry::from(volume.dims, volume.spacing, a.settings.z_scale);
  DeviceField field(*ctx, volume.values, "bench field");
  Buffer tf_buffer = upload_tf(*ctx, tf, "bench TF");
  const FieldMapping mapping = make_mapping(range, uint32_t(tf.size()));
  GpuRenderer renderer(*ctx, field, geometry);

  nlohmann::json results = nlohmann::json::array();
  std::printf("bench-render on %s: %llu^3 synthetic_reference, demo TF, step %g voxels, opacity scale %g,\n"
              "  camera azimuth %g elevation %g distance %g fov %g; GPU: best of %u (GPU timestamps when available;\n"
              "  call ms: the best whole render_colours call, allocation, submission and read-back included)\n"
              "  CPU reference: double precision, one thread, the %u middle rows of each image (its rate is\n"
              "  samples/s over those rows; samples there are the densest of the image)\n\n",
              ctx->device_name().c_str(), static_cast<unsigned long long>(a.size), a.settings.step_voxels,
              a.settings.opacity_scale, a.settings.camera.azimuth_deg, a.settings.camera.elevation_deg,
              a.settings.camera.distance, a.settings.camera.fov_deg, a.repeat, a.cpu_rows);
  std::printf("%-11s %10s %10s %14s %16s %14s %8s\n", "image", "GPU ms", "call ms", "samples", "GPU Msamples/s",
              "CPU Msamples/s", "ratio");
  for (uint32_t size : a.images) {
    RenderSettings s = a.settings;
    s.width = s.height = size;
    renderer.render(mapping, tf_buffer, s);  // warm-up: pipeline and first-touch costs
    double best_ms = 1e300, best_call_ms = 1e300;
    uint64_t samples = 0;
    for (uint32_t r = 0; r < a.repeat; ++r) {
      double gpu_ms = -1;
      const auto t0 = std::chrono::steady_clock::now();
      RenderedImage img = renderer.render(mapping, tf_buffer, s, nullptr, &gpu_ms);
      const double wall = ms_since(t0);
      best_ms = std::min(best_ms, gpu_ms > 0 ? gpu_ms : wall);
      samples = img.samples();
      // A picture as the viewer and reports ask for one: the whole call, read-back included.
      const auto t1 = std::chrono::steady_clock::now();
      renderer.render_colours(mapping, tf_buffer, s);
      best_call_ms = std::min(best_call_ms, ms_since(t1));
    }
    CpuRenderOptions co;
    co.row_begin = size / 2 - std::min(a.cpu_rows, size) / 2;
    co.row_end = co.row_begin + std::min(a.cpu_rows, size);
    Progress progress("CPU reference " + std::to_string(size), co.row_end - co.row_begin);
    co.progress = [&](uint32_t rows) { progress.update(rows); };
    const auto t0 = std::chrono::steady_clock::now();
    const CpuRender cpu = render_cpu(volume, tf, range, s, co);
    const double cpu_ms = ms_since(t0);
    progress.finish();
    const double gpu_rate = double(samples) / (best_ms * 1e-3);
    const double cpu_rate = double(cpu.samples) / (cpu_ms * 1e-3);
    std::printf("%4ux%-6u %10.2f %10.2f %14llu %16.1f %14.2f %8.1f\n", size, size, best_ms, best_call_ms,
                static_cast<unsigned long long>(samples), gpu_rate * 1e-6, cpu_rate * 1e-6, gpu_rate / cpu_rate);
    std::fflush(stdout);
    results.push_back({{"image", size},
                       {"gpu_ms", best_ms},
                       {"call_ms", best_call_ms},
                       {"samples", samples},
                       {"gpu_samples_per_s", gpu_rate},
                       {"cpu_rows", co.row_end - co.row_begin},
                       {"cpu_samples", cpu.samples},
                       {"cpu_ms", cpu_ms},
                       {"cpu_samples_per_s", cpu_rate},
                       {"ratio", gpu_rate / cpu_rate}});
  }
  json.write({{"device", ctx->device_name()}, {"volume", a.size}, {"results", results}});
  return 0;
}

CommandRegistration reg(91, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand("bench-render", "Benchmark the GPU renderer against the CPU reference renderer");
  sub->add_option("--size", args->size, "Volume size per axis")->check(CLI::Range(8, 1024))->capture_default_str();
  sub->add_option("--images", args->images, "Image sizes (square), comma separated")->delimiter(',')
      ->check(CLI::Range(8u, 8192u))->capture_default_str();
  sub->add_option("--repeat", args->repeat, "GPU renders per size (the best counts)")->check(CLI::Range(1u, 100u))
      ->capture_default_str();
  sub->add_option("--cpu-rows", args->cpu_rows, "Rows the CPU reference renders per size")
      ->check(CLI::Range(1u, 8192u))->capture_default_str();
  add_json_option(sub, args->json, "the results");
  add_render_options(sub, args->settings);
  remove_options(sub, {"--width", "--height"});  // --images gives the sizes
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
