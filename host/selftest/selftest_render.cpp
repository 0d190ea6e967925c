// Self-test cases of the ray-marching kernels against the double-precision CPU references:
// render_image (forward, several views per dispatch, row bands, and its inverse-check mode),
// diffdvr_forward (final state C, T), visibility_weights (per voxel) and diffdvr_backward (loss and TF gradient vs the CPU reverse
// mode of host/reference/diffdvr_cpu.h, l2 and l1, shared-memory and global paths).
#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/diffdvr.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/kernels/visibility_weights.h"
#include "tfmatch/model/camera.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "tfmatch/reference/diffdvr_cpu.h"
#include "tfmatch/reference/visibility_weights_cpu.h"
#include "tfmatch/selftest/selftest_support.h"

namespace tfm::selftest {
namespace {

// Smooth structure plus deterministic noise, so TF lookups cross many entries; NaN at every
// `nan_every`-th voxel (from 3).
Volume wavy_volume(std::array<uint64_t, 3> dims, std::array<double, 3> spacing, uint32_t seed, int nan_every = 0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-0.08f, 0.08f);
  Volume v;
  v.dims = dims;
  v.spacing = spacing;
  v.name = "selftest volume";
  v.values.resize(v.voxel_count());
  size_t i = 0;
  for (uint64_t z = 0; z < dims[2]; ++z)
    for (uint64_t y = 0; y < dims[1]; ++y)
      for (uint64_t x = 0; x < dims[0]; ++x, ++i) {
        v.values[i] = 0.5f + 0.35f * std::sin(0.7f * x + 0.3f * y + 0.1f * seed) * std::cos(0.5f * z - 0.2f * x) +
                      noise(rng);
        if (nan_every && i % nan_every == 3) v.values[i] = NAN;
        if (nan_every && i % (3 * nan_every) == 5) v.values[i] = i % 2 ? INFINITY : -INFINITY;  // no data too
      }
  return v;
}

OrbitCamera camera(double azimuth, double elevation, double distance = 2.4) {
  OrbitCamera c;
  c.azimuth_deg = azimuth;
  c.elevation_deg = elevation;
  c.distance = distance;
  c.fov_deg = 40;
  return c;
}

struct Scene {
  Volume volume;
  TransferFunction tf;
  FieldRange range{0.0, 1.0};
  RenderSettings settings;           // image size and optics; poses come from `cameras`
  std::vector<OrbitCamera> cameras;  // rendered in one dispatch (one view each)
  uint64_t chunk_voxels = 0;         // field chunks (0: one)
  uint32_t bands = 1;                // row bands, one dispatch each
  uint32_t max_part_samples = 0;     // > 0: rays marched in parts of these many samples
  // Share of the pixels whose rays must reach the termination opacity (0.99) in the reference:
  // a scene that claims to exercise early termination must.
  double min_stopped = 0.0;
};

RenderSettings settings(uint32_t width, uint32_t height, double opacity_scale, double step_voxels = 0.37) {
  RenderSettings s;
  s.width = width;
  s.height = height;
  s.step_voxels = step_voxels;  // not a divisor of the box: sample counts vary from ray to ray
  s.opacity_scale = opacity_scale;
  return s;
}

RenderSettings posed(const Scene& scene, size_t view) {
  RenderSettings s = scene.settings;
  s.camera = scene.cameras[view];
  return s;
}

// The device's images of every view: 4 floats and a stop index per pixel, views one after the
// other. `Kernel` is RenderImageKernel or DiffDvrForwardKernel (the same recording interface).
struct DeviceImages {
  std::vector<float> rgba;
  std::vector<uint32_t> stop;
};

struct DeviceScene {
  DeviceScene(Context& ctx, const Scene& s)
      : geometry(VolumeGeometry::from(s.volume.dims, s.volume.spacing)),
        field(ctx, s.volume.values, "selftest field", s.chunk_voxels),
        tf(upload_tf(ctx, s.tf, "selftest TF")) {
    std::vector<gpu::RenderView> records;
    for (const OrbitCamera& cam : s.cameras)
      records.push_back(make_render_view(orbit_frame(cam, geometry, s.settings.width, s.settings.height)));
    views = make_buffer<gpu::RenderView>(ctx, records, "selftest cameras");
    push = make_render_push(geometry, march_constants(s.settings, geometry),
                            make_mapping(s.range, uint32_t(s.tf.size())), field, s.settings.width, s.settings.height,
                            uint32_t(s.cameras.size()));
    const uint64_t pixels = uint64_t(s.settings.width) * s.settings.height * s.cameras.size();
    image = Buffer(ctx, pixels * 16, MemoryUsage::Device, "selftest image");
    stop = Buffer(ctx, pixels * 4, MemoryUsage::Device, "selftest stop index");
  }
  template <class Kernel>
  DeviceImages render(Context& ctx, const Kernel& kernel, uint32_t bands) {
    const uint32_t height = push.height, band = (height + bands - 1) / bands;
    CommandBatch batch(ctx);
    // Bands write disjoint rows: no barrier between them.
    for (uint32_t row = 0; row < height; row += band)
      kernel.record(batch, field, tf, views, push, image, stop, row, std::min(band, height - row));
    batch.submit_and_wait();
    const uint64_t pixels = uint64_t(push.width) * push.height * push.view_count;
    DeviceImages out{std::vector<float>(pixels * 4), std::vector<uint32_t>(pixels)};
    readback(ctx, image, out.rgba.data(), pixels * 16);
    readback(ctx, stop, out.stop.data(), pixels * 4);
    return out;
  }
  VolumeGeometry geometry;
  DeviceField field;
  Buffer tf, views, image, stop;
  gpu::RenderPush push{};
};

enum class Output { Image, State };  // (premultiplied RGB, opacity) or (premultiplied RGB, T)

// Bound 5e-5 per component (tests/kernels/test_render_gpu.cpp): the device rounds sample positions
// (|p| < 100 voxels: < 1e-5 voxel), trilinear and TF weights in float, and exp() and normalize()
// may be off by a few ulp (GLSL allows exp 3 + 2|x| ulp); a ray composites <= ~150 such steps.
// Pixels where float may legitimately take another discrete decision than double (sample count
// at a half integer, transmittance at the stop threshold, a sample on a face where NaN corners
// change) are left out, as the CPU renderer flags them; they must stay rare (<= 5% + 1). Stop
// indices of the others are exact. The rays must hit the volume (> 5% of the pixels covered).
void compare_images(Check& check, const Scene& s, const DeviceImages& g, Output output) {
  const size_t pixels = size_t(s.settings.width) * s.settings.height;
  size_t ambiguous = 0, covered = 0;
  for (size_t v = 0; v < s.cameras.size(); ++v) {
    CpuRenderOptions options;
    options.track_ambiguity = true;
    const CpuRender r = render_cpu(s.volume, s.tf, s.range, posed(s, v), options);
    for (size_t p = 0; p < pixels; ++p) {
      if (r.ambiguous[p]) {
        ++ambiguous;
        continue;
      }
      covered += r.stop[p] > 0;
      const size_t at = v * pixels + p;
      check.equal("stop index of pixel (view * pixels + pixel)", at, g.stop[at], r.stop[p]);
      for (int c = 0; c < 4; ++c) {
        const double reference = (output == Output::State && c == 3) ? 1.0 - r.rgba[4 * p + 3] : r.rgba[4 * p + c];
        check.near("component (4 * pixel + c)", 4 * at + c, g.rgba[4 * at + c], reference, 5e-5);
      }
    }
  }
  const size_t total = pixels * s.cameras.size();
  check.require(ambiguous <= total / 20 + 1, std::to_string(ambiguous) + " of " + std::to_string(total) +
                                                  " pixels are ambiguous between float and double");
  check.require(covered > total / 20, "the volume covers too little of the images to test anything");
}

void render(Context& ctx, Check& check, const Scene& s) {
  if (s.min_stopped > 0.0) {
    size_t stopped = 0, total = 0;
    for (size_t v = 0; v < s.cameras.size(); ++v) {
      const CpuRender r = render_cpu(s.volume, s.tf, s.range, posed(s, v));
      for (size_t p = 0; p < r.stop.size(); ++p, ++total) stopped += r.rgba[4 * p + 3] >= 0.99;
    }
    check.require(double(stopped) > s.min_stopped * double(total), "the scene does not exercise early termination");
  }
  DeviceScene d(ctx, s);
  const RenderImageKernel kernel(ctx, uint32_t(d.field.chunk_count()), TFM_RENDER_MODE_FORWARD, s.max_part_samples);
  compare_images(check, s, d.render(ctx, kernel, s.bands), Output::Image);
}

void forward(Context& ctx, Check& check, const Scene& s) {
  DeviceScene d(ctx, s);
  const DiffDvrForwardKernel kernel(ctx, uint32_t(d.field.chunk_count()), s.max_part_samples);
  compare_images(check, s, d.render(ctx, kernel, s.bands), Output::State);
}

// The inverse-check mode re-marches each ray backwards from its final state, undoing every
// compositing step, and writes the recovered start state, which is exactly 0. Float round-off of
// <= ~150 steps of one division and one multiply-subtract each bounds it well below 1e-4
// (tests/kernels/test_render_gpu.cpp). Rays must reach the termination opacity somewhere.
void inverse_check(Context& ctx, Check& check, const Scene& s) {
  DeviceScene d(ctx, s);
  const RenderImageKernel kernel(ctx, uint32_t(d.field.chunk_count()), TFM_RENDER_MODE_INVERSE_CHECK);
  const DeviceImages g = d.render(ctx, kernel, s.bands);
  for (size_t k = 0; k < g.rgba.size(); ++k) check.near("recovered start state (4 * pixel + c)", k, g.rgba[k], 0.0, 1e-4);
  double max_opacity = 0.0;
  for (size_t v = 0; v < s.cameras.size(); ++v) {
    const CpuRender r = render_cpu(s.volume, s.tf, s.range, posed(s, v));
    for (size_t p = 0; p < r.stop.size(); ++p) max_opacity = std::max(max_opacity, r.rgba[4 * p + 3]);
  }
  check.require(max_opacity > 0.99, "no ray reached the termination opacity");
}

// The visibility weights of the scene's field and TF over its cameras (the optical model of its
// settings) against the double reference. The bound: the quantization to multiples of 2^-16
// (2^-17) plus float marching against double (lavapipe: 7.7e-6 in all).
void visibility(Context& ctx, Check& check, const Scene& s) {
  DeviceScene d(ctx, s);
  const VisibilityWeightsKernel kernel(ctx, uint32_t(d.field.chunk_count()));
  const VisibilityWeights gpu = kernel.compute(d.field, d.geometry, make_mapping(s.range, uint32_t(s.tf.size())), d.tf,
                                               s.settings, s.cameras, s.max_part_samples);
  const CpuVisibilityWeights cpu = visibility_weights_cpu(s.volume, s.tf, s.range, s.settings, s.cameras, true);
  check.near("largest sum of transmittances", 0, gpu.max_sum, cpu.max_sum, 1e-4 * cpu.max_sum);
  size_t ambiguous = 0;
  for (size_t c = 0; c < gpu.weights.chunk_count(); ++c) {
    std::vector<float> w(gpu.weights.chunk_size(c));
    readback(ctx, gpu.weights.chunk(c), w.data(), w.size() * 4);
    for (size_t i = 0; i < w.size(); ++i) {
      const size_t voxel = gpu.weights.chunk_begin(c) + i;
      if (cpu.ambiguous[voxel]) {
        ++ambiguous;  // a sample on the edge of a NaN cell: float and double may both be right
        continue;
      }
      check.near("weight (voxel)", voxel, w[i], cpu.weights[voxel], 1e-4);
    }
  }
  check.require(ambiguous * 2 < cpu.weights.size(), "half of the voxels ambiguous: the scene tests little");
}

struct GradientScene {
  Scene field;              // the field, the TF being optimized, the cameras
  Volume reference;         // rendered with ref_tf into the target images
  TransferFunction ref_tf;
  ImageLoss loss = ImageLoss::L2;
  ReductionMode mode = ReductionMode::RunsShared;  // of the backward kernel
  RunsMarch march = RunsMarch::Auto;               // of its runs modes
  uint32_t max_part_samples = 0;                   // > 0: a flat march back in parts of these many
};

// The target images: the CPU reference's renders of the reference field, as floats in the
// forward state's layout (C, T), view after view.
std::vector<float> target_images(const GradientScene& gs) {
  const Scene& s = gs.field;
  const size_t pixels = size_t(s.settings.width) * s.settings.height;
  std::vector<float> target(4 * pixels * s.cameras.size());
  for (size_t v = 0; v < s.cameras.size(); ++v) {
    const CpuRender r = render_cpu(gs.reference, gs.ref_tf, s.range, posed(s, v));
    for (size_t p = 0; p < pixels; ++p) {
      for (int c = 0; c < 3; ++c) target[4 * (v * pixels + p) + c] = float(r.rgba[4 * p + c]);
      target[4 * (v * pixels + p) + 3] = float(1.0 - r.rgba[4 * p + 3]);
    }
  }
  return target;
}

// The backward pass's accumulator words for `gs` against `target` with its runs marched as
// `march`: the forward pass, then the backward pass, in one submission.
std::vector<uint32_t> backward_words(Context& ctx, const GradientScene& gs, const std::vector<float>& target,
                                     RunsMarch march) {
  const Scene& s = gs.field;
  const uint32_t n = uint32_t(s.tf.size());
  DeviceScene d(ctx, s);
  const DiffDvrForwardKernel forward_kernel(ctx, uint32_t(d.field.chunk_count()));
  const DiffDvrBackwardKernel backward_kernel(ctx, uint32_t(d.field.chunk_count()), n, gs.loss, gs.mode, march,
                                              gs.max_part_samples);
  Buffer target_buffer = make_buffer<float>(ctx, target, "selftest target images");
  Buffer accum(ctx, uint64_t(backward_kernel.slots()) * 8, MemoryUsage::Device, "selftest DiffDVR accumulators");
  const uint64_t resume_bytes = backward_kernel.resume_bytes(d.push);
  Buffer resume(ctx, std::max<uint64_t>(resume_bytes, 4), MemoryUsage::Device, "selftest DiffDVR ray states");
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  forward_kernel.record(batch, d.field, d.tf, d.views, d.push, d.image, d.stop, 0, s.settings.height);
  // The forward state and the zeroed accumulators before the backward pass reads them.
  batch.barrier();
  backward_kernel.record(batch, d.field, d.tf, d.views, d.push, d.image, d.stop, target_buffer, accum, 0,
                         s.settings.height, &resume);
  batch.submit_and_wait();
  return read_words(ctx, accum, size_t(backward_kernel.slots()) * 2);
}

std::vector<double> fixed_point_totals(const std::vector<uint32_t>& words) {
  FixedPointTotals totals(words.size() / 2);
  totals.add(words.data());
  return totals.values();
}

// The backward pass's loss and TF gradient against the CPU reverse mode, both from the same
// target images (the CPU reference's renders of the reference field, uploaded as floats) and
// summed over the views. Bounds (tests/kernels/test_diffdvr_gradient.cpp, test_diffdvr_reverse.cpp),
// relative to the largest gradient entry as terms of both signs cancel in single entries: 5e-5.
// The device rounds the TF coordinate in float (|dw| <= 2^-24 (N-1)), sample positions and
// trilinear weights (~1e-7), exp() (a few ulp), and T recovered by K ~ 30 divisions drifts by
// ~K ulp (2e-6). The loss: 1e-4 relative.
void backward(Context& ctx, Check& check, const GradientScene& gs) {
  const Scene& s = gs.field;
  const uint32_t n = uint32_t(s.tf.size());
  if (const std::string why = DiffDvrBackwardKernel::unsupported(ctx, n, gs.mode); !why.empty())
    return check.skip(why);
  const size_t pixels = size_t(s.settings.width) * s.settings.height;
  std::vector<double> cpu_gradient(4 * size_t(n), 0.0);
  const std::vector<float> target = target_images(gs);
  double cpu_loss = 0.0;
  for (size_t v = 0; v < s.cameras.size(); ++v) {
    // The CPU reverse mode against the same (float) targets, opacity = 1 - T.
    std::vector<double> rounded(4 * pixels);
    for (size_t p = 0; p < pixels; ++p) {
      for (int c = 0; c < 3; ++c) rounded[4 * p + c] = target[4 * (v * pixels + p) + c];
      rounded[4 * p + 3] = 1.0 - double(target[4 * (v * pixels + p) + 3]);
    }
    const CpuLossGradient cg = image_loss_gradient_cpu(s.volume, s.tf, s.range, posed(s, v), rounded, gs.loss);
    cpu_loss += cg.loss;
    for (uint32_t j = 0; j < n; ++j)
      for (int c = 0; c < 4; ++c) cpu_gradient[4 * j + c] += cg.gradient[j][c];
  }

  const std::vector<double> sums = fixed_point_totals(backward_words(ctx, gs, target, gs.march));

  double scale = 0.0;
  for (double g : cpu_gradient) scale = std::max(scale, std::abs(g));
  check.near("loss", 0, sums.back(), cpu_loss, 1e-4 * cpu_loss);
  for (size_t k = 0; k < cpu_gradient.size(); ++k)
    check.near("gradient (4j+c)", k, sums[k], cpu_gradient[k], 5e-5 * scale);
  check.require(scale > 0.0, "the gradient is zero: the case tests nothing");
}

// The runs modes' two marches (RunsMarch) on one scene: the same runs and sums, so the same
// accumulator bits, word for word.
void backward_marches(Context& ctx, Check& check, const GradientScene& gs) {
  const uint32_t n = uint32_t(gs.field.tf.size());
  if (const std::string why = DiffDvrBackwardKernel::unsupported(ctx, n, gs.mode); !why.empty()) return check.skip(why);
  const std::vector<float> target = target_images(gs);
  const std::vector<uint32_t> nested = backward_words(ctx, gs, target, RunsMarch::Nested);
  const std::vector<uint32_t> flat = backward_words(ctx, gs, target, RunsMarch::Flat);
  for (size_t k = 0; k < nested.size(); ++k) check.equal("accumulator word (flat vs nested)", k, flat[k], nested[k]);
  bool any = false;
  for (uint32_t w : nested) any = any || w != 0;
  check.require(any, "the accumulators are zero: the case tests nothing");
}

std::vector<OrbitCamera> cameras(std::initializer_list<std::pair<double, double>> poses, double distance = 2.4) {
  std::vector<OrbitCamera> out;
  for (auto [azimuth, elevation] : poses) out.push_back(camera(azimuth, elevation, distance));
  return out;
}

// Entries with colours in [c_lo, c_hi] and opacity in [a_lo, a_hi].
TransferFunction tf_in(uint32_t n, uint32_t seed, double c_lo, double c_hi, double a_lo, double a_hi) {
  TransferFunction tf = random_tf(n, seed, c_lo, c_hi);
  std::mt19937 rng(seed + 1000);
  std::uniform_real_distribution<double> a(a_lo, a_hi);
  for (auto& e : tf.rgba) e[3] = a(rng);
  return tf;
}

// The DiffDVR scene of tests/kernels/test_diffdvr_reverse.cpp: two noisy fields, three views from above,
// oblique and below, 24x24 pixels.
GradientScene gradient_scene(std::array<uint64_t, 3> dims, uint32_t tf_size, uint32_t width, uint32_t height,
                             int nan_every = 0) {
  GradientScene gs;
  gs.field.volume = wavy_volume(dims, {1.0, 1.0, 1.0}, 12, nan_every);
  gs.reference = wavy_volume(dims, {1.0, 1.0, 1.0}, 11, nan_every);
  gs.field.tf = random_tf(tf_size, 14);
  gs.ref_tf = random_tf(5, 13);
  gs.field.settings = settings(width, height, 10.0, 0.61);
  gs.field.cameras = cameras({{15, 90}, {40, 25}, {250, -60}}, 2.3);
  return gs;
}

}  // namespace

void add_render_cases(CaseList& cases) {
  const Workgroup render_tile(TFM_RENDER_TILE, TFM_RENDER_TILE);
  const uint32_t render_buffers = TFM_RENDER_MAX_CHUNKS + 4;  // field chunk array, TF, views, image, stop
  auto add = [&](const char* kernel, const char* wrapper, const std::string& name, bool quick, Workgroup group,
                 uint32_t buffers, auto body, auto scene) {
    cases.push_back({kernel, wrapper, name, quick, group,
                     [body, scene](Context& ctx, Check& check) { body(ctx, check, scene); }, buffers});
  };

  // ---- render_image and diffdvr_forward: the same scenes ----
  std::vector<std::pair<std::string, Scene>> quick_scenes, full_scenes;
  {
    Scene s;  // anisotropic spacing, several views in one dispatch, rows in two bands
    s.volume = wavy_volume({13, 7, 5}, {1.0, 2.0, 0.5}, 1);
    s.tf = random_tf(17, 2);
    s.range = {0.1, 0.9};
    s.settings = settings(13, 9, 6.0);  // 9 rows: one past the 8x8 tile
    // Oblique views, axis-aligned views (rays parallel to grid planes), and both poles.
    s.cameras = cameras({{30, 20}, {0, 90}, {123, -90}, {200, -35}, {0, 0}, {90, 0}, {-45, 60}});
    s.bands = 2;
    quick_scenes.emplace_back("13x7x5 grid, spacing 1:2:0.5, 13x9 image, 7 views incl. both poles, 2 row bands", s);
  }
  {
    Scene s;  // 3 buffers of 500 voxels: trilinear corners of one sample fall into different chunks
    s.volume = wavy_volume({13, 11, 9}, {1.0, 1.0, 1.0}, 3, 29);
    s.tf = random_tf(8, 4);
    s.settings = settings(17, 16, 6.0);
    s.cameras = cameras({{30, 20}, {0, 90}, {0, 0}});
    s.chunk_voxels = 500;
    quick_scenes.emplace_back("NaNs, field in 3 chunks, 17x16 image, 3 views", s);
    // Rays in parts, as on llvmpipe beyond ~65 000 samples, here of 5 samples on every device.
    s.max_part_samples = 5;
    quick_scenes.emplace_back("NaNs, field in 3 chunks, 17x16 image, 3 views, rays in parts of 5 samples", s);
  }
  {
    Scene s;  // opaque: most rays stop at opacity 0.99 well before leaving the box
    s.volume = wavy_volume({16, 16, 16}, {1.0, 1.0, 1.0}, 5);
    s.tf = random_tf(12, 6);
    for (auto& e : s.tf.rgba) e[3] = 0.5 + 0.5 * e[3];
    s.settings = settings(15, 15, 60.0);
    s.cameras = cameras({{30, 20}});
    s.min_stopped = 0.25;
    quick_scenes.emplace_back("early termination, 16^3 grid, 15x15 image", s);
    s.max_part_samples = 5;  // rays that stopped stay stopped in the parts after
    quick_scenes.emplace_back("early termination, 16^3 grid, 15x15 image, rays in parts of 5 samples", s);
  }
  {
    Scene s;
    s.volume = wavy_volume({1, 1, 1}, {1.0, 1.0, 1.0}, 8);
    s.tf = random_tf(5, 7);
    s.settings = settings(9, 9, 20.0);
    s.cameras = cameras({{30, 20}});
    quick_scenes.emplace_back("1x1x1 grid, 9x9 image", s);
    s.volume = wavy_volume({1, 9, 4}, {1.0, 1.0, 1.0}, 9);
    s.settings = settings(8, 9, 20.0);
    s.cameras = cameras({{90, 10}});
    quick_scenes.emplace_back("1x9x4 grid, 8x9 image", s);
    // (From (30, 20) its one ray's transmittance passes the stop threshold within the ambiguity
    // tolerance since its samples weigh chord / K: nothing would be compared.)
    s.cameras = cameras({{35, 20}});
    s.volume = wavy_volume({6, 5, 4}, {1.0, 1.0, 1.0}, 10);
    s.settings = settings(1, 1, 20.0);
    quick_scenes.emplace_back("6x5x4 grid, 1x1 image", s);
  }
  {
    // Larger, within the regime the bound is argued for: positions below 100 voxels, a TF of 17
    // entries (the colour's slope in the field value, which multiplies position rounding, grows
    // with N; at N = 64 random entries lavapipe lands at 8e-5 on this grid, here at 1.9e-5).
    Scene s;
    s.volume = wavy_volume({48, 40, 32}, {1.0, 1.0, 1.5}, 9, 97);
    s.tf = random_tf(17, 10);
    s.settings = settings(96, 80, 8.0);
    s.cameras = cameras({{30, 20}, {0, 90}, {200, -35}, {-45, 60}});
    s.chunk_voxels = 16384;
    s.bands = 3;
    full_scenes.emplace_back("48x40x32 grid with NaNs in 4 chunks, 96x80 image, 4 views, 3 row bands", s);
  }
  Scene inverse;  // the inverse check of tests/kernels/test_render_gpu.cpp
  inverse.volume = wavy_volume({16, 12, 10}, {1.0, 1.0, 1.5}, 13, 31);
  inverse.tf = random_tf(16, 14);
  inverse.settings = settings(16, 12, 40.0);
  inverse.cameras = cameras({{40, 25}, {0, 90}});
  inverse.chunk_voxels = 700;
  for (bool quick : {true, false})
    for (const auto& [name, scene] : quick ? quick_scenes : full_scenes)
      add("render_image", "RenderImageKernel", name, quick, render_tile, render_buffers, render, scene);
  add("render_image", "RenderImageKernel", "inverse-check mode, NaNs, field in 3 chunks, 2 views", true, render_tile,
      render_buffers, inverse_check, inverse);
  for (bool quick : {true, false})
    for (const auto& [name, scene] : quick ? quick_scenes : full_scenes)
      add("diffdvr_forward", "DiffDvrForwardKernel", name, quick, render_tile, render_buffers, forward, scene);
  // visibility_weights: the same fields, TFs and cameras (one weight a voxel; the image size
  // gives the frustum's aspect).
  for (bool quick : {true, false})
    for (const auto& [name, scene] : quick ? quick_scenes : full_scenes)
      add("visibility_weights", "VisibilityWeightsKernel", name, quick, Workgroup(64), TFM_RENDER_MAX_CHUNKS + 3,
          visibility, scene);

  // ---- diffdvr_backward ----
  const Workgroup backward_tile(TFM_DIFFDVR_BACKWARD_TILE, TFM_DIFFDVR_BACKWARD_TILE);
  const uint32_t backward_buffers = TFM_RENDER_MAX_CHUNKS + 6;
  auto add_backward = [&](const std::string& name, bool quick, const GradientScene& gs) {
    add("diffdvr_backward", "DiffDvrBackwardKernel", name, quick, backward_tile, backward_buffers, backward, gs);
  };
  {
    GradientScene gs = gradient_scene({10, 8, 7}, 13, 24, 24, 17);
    gs.field.chunk_voxels = gs.reference.voxel_count() / 3 + 1;
    add_backward("l2, NaNs, field in 3 chunks, 24x24 image, 3 views, shared memory", true, gs);
    gs.march = RunsMarch::Nested;
    add_backward("l2, NaNs, field in 3 chunks, 24x24 image, 3 views, shared memory, nested march", true, gs);
    add("diffdvr_backward", "DiffDvrBackwardKernel",
        "l2, NaNs, 24x24 image, 3 views: flat and nested marches, same bits", true, backward_tile, backward_buffers,
        backward_marches, gs);
    // Rays marched back in parts of 7 samples (as on llvmpipe beyond ~65 000), the ray states
    // kept between them: runs flushed at the parts' edges, within the same bound.
    gs.march = RunsMarch::Flat;
    gs.max_part_samples = 7;
    add_backward("l2, NaNs, field in 3 chunks, 24x24 image, 3 views, shared memory, rays back in parts of 7", true,
                 gs);
    gs.mode = ReductionMode::RunsGlobal;
    add_backward("l2, NaNs, field in 3 chunks, 24x24 image, 3 views, global atomics, rays back in parts of 7", true,
                 gs);
    gs.max_part_samples = 0;
    gs.march = RunsMarch::Auto;
    add_backward("l2, NaNs, field in 3 chunks, 24x24 image, 3 views, global atomics", true, gs);
    gs.mode = ReductionMode::Private;
    add_backward("l2, NaNs, field in 3 chunks, 24x24 image, 3 views, private histograms", true, gs);
  }
  {
    // The reference is more opaque and redder in every channel than the field can be, so every
    // covered pixel has X - R clearly away from 0 (the l1 kink) in all four components.
    GradientScene gs = gradient_scene({9, 7, 6}, 7, 24, 24);
    gs.loss = ImageLoss::L1;
    gs.ref_tf = tf_in(9, 3, 0.6, 0.9, 0.6, 0.9);
    gs.field.tf = tf_in(7, 4, 0.1, 0.4, 0.1, 0.4);
    gs.field.settings.opacity_scale = 20.0;
    add_backward("l1, 24x24 image, 3 views", true, gs);
  }
  {
    // Opacity scale 3000: one step at TF opacity > 0.15 has optical depth > 20, so its
    // transmittance is clamped at exp(-20) and the inversion divides by tau ~ 2e-9.
    GradientScene gs = gradient_scene({9, 7, 6}, 7, 24, 24);
    gs.field.settings.opacity_scale = 3000.0;
    add_backward("l2, optical-depth clamp active, 24x24 image, 3 views", true, gs);
  }
  add_backward("l2, 17x13 image (one past the 16x16 tile), N=2", true, gradient_scene({6, 5, 4}, 2, 17, 13));
  {
    // Lanes march 4 rows 16 apart: 70 rows end inside a lane's third row.
    GradientScene gs = gradient_scene({6, 5, 4}, 11, 17, 70);
    gs.mode = ReductionMode::Private;
    add_backward("l2, 17x70 image, N=11, private histograms", true, gs);
  }
  add_backward("l2, 1x1 image, N=127", true, gradient_scene({5, 9, 3}, 127, 1, 1));
  {
    GradientScene gs = gradient_scene({24, 20, 18}, 64, 48, 40, 41);
    gs.field.cameras = cameras({{15, 90}, {40, 25}, {250, -60}, {120, 5}}, 2.3);
    gs.field.chunk_voxels = 4096;
    add_backward("l2, 24x20x18 grid with NaNs in 3 chunks, 48x40 image, 4 views, N=64", false, gs);
  }
}

}  // namespace tfm::selftest
