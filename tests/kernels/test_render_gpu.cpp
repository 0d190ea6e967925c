// GPU renderer against the double-precision CPU reference: awkward volume and image sizes,
// anisotropic spacing, several cameras (straight down and up the z axis included), NaNs, fields
// split into several buffers, early termination; plus the DiffDVR inversion self-check.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "commands.h"
#include "cpu_renderer.h"
#include "gpu_voxel_ops.h"
#include "render.h"
#include "test_data.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

// Smooth structure plus deterministic noise, so TF lookups cross many entries.
Volume test_volume(std::array<uint64_t, 3> dims, std::array<double, 3> spacing, uint32_t seed, int nan_every = 0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-0.08f, 0.08f);
  return test::make_volume(dims, spacing, "test volume", [&](uint64_t x, uint64_t y, uint64_t z, uint64_t i) {
    const float v = 0.5f + 0.35f * std::sin(0.7f * x + 0.3f * y) * std::cos(0.5f * z - 0.2f * x) + noise(rng);
    return nan_every && i % nan_every == 3 ? NAN : v;
  });
}

using test::random_tf;

struct CameraCase {
  double azimuth, elevation;
};
// Oblique views, axis-aligned views (rays parallel to grid planes), and both poles.
const CameraCase kCameras[] = {{30, 20}, {0, 90}, {123, -90}, {200, -35}, {0, 0}, {90, 0}, {-45, 60}};

class RenderGpu : public test::GpuTest {
 protected:
  // Renders on both sides and compares every pixel whose discrete decisions cannot differ
  // between float and double (see CpuRenderOptions::track_ambiguity).
  //
  // Tolerance 5e-5 per RGBA component. The GPU rounds sample positions (|p| < 100 voxels here:
  // < 1e-5 voxel), trilinear and TF weights in float, and exp() and normalize() may be off by a
  // few ulp (GLSL allows exp 3 + 2|x| ulp); a ray composites <= 100 such steps. Lavapipe agrees
  // to 2e-6 (printed below); 5e-5 leaves margin for other drivers and is still 1/80 of one
  // 8-bit level, so a passing pixel can never change the PNG by more than one level.
  void compare(const Volume& vol, const TransferFunction& tf, const FieldRange& range, const RenderSettings& s,
               uint64_t max_chunk_voxels = 0, double* max_err_out = nullptr) {
    const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing);
    DeviceField field(ctx(), vol.values, "test field", max_chunk_voxels);
    Buffer tf_buf = upload_tf(ctx(), tf, "test TF");
    GpuRenderer renderer(ctx(), field, geo);
    const RenderedImage gpu = renderer.render(make_mapping(range, uint32_t(tf.size())), tf_buf, s);
    CpuRenderOptions opt;
    opt.track_ambiguity = true;
    const CpuRender cpu = render_cpu(vol, tf, range, s, opt);
    ASSERT_EQ(gpu.rgba.size(), cpu.rgba.size());
    size_t ambiguous = 0, covered = 0;
    double max_err = 0.0;
    for (size_t p = 0; p < cpu.stop.size(); ++p) {
      if (cpu.ambiguous[p]) {
        ++ambiguous;
        continue;
      }
      if (cpu.stop[p] > 0) ++covered;
      ASSERT_EQ(gpu.stop[p], cpu.stop[p]) << "pixel (" << p % s.width << ", " << p / s.width << ")";
      for (int c = 0; c < 4; ++c) {
        const double err = std::abs(double(gpu.rgba[4 * p + c]) - cpu.rgba[4 * p + c]);
        max_err = std::max(max_err, err);
        ASSERT_LE(err, 5e-5) << "pixel (" << p % s.width << ", " << p / s.width << ") channel " << c << ": gpu "
                             << gpu.rgba[4 * p + c] << " cpu " << cpu.rgba[4 * p + c];
      }
    }
    // The exemption must stay rare, and the rays must actually hit the volume.
    EXPECT_LE(ambiguous, cpu.stop.size() / 20 + 1) << "too many pixels exempted as ambiguous";
    EXPECT_GT(covered, cpu.stop.size() / 20) << "the volume covers too little of the image to test anything";
    if (max_err_out) *max_err_out = std::max(*max_err_out, max_err);
  }

  static RenderSettings settings(uint32_t w, uint32_t h, CameraCase cam, double opacity_scale = 6.0) {
    RenderSettings s;
    s.width = w;
    s.height = h;
    s.step_voxels = 0.37;  // not a divisor of the box: sample counts vary from ray to ray
    s.opacity_scale = opacity_scale;
    s.camera.azimuth_deg = cam.azimuth;
    s.camera.elevation_deg = cam.elevation;
    s.camera.distance = 2.4;
    s.camera.fov_deg = 40;
    return s;
  }
};

TEST_F(RenderGpu, MatchesCpuReferenceOnAwkwardGridsFromManyCameras) {
  const Volume vol = test_volume({13, 7, 5}, {1.0, 2.0, 0.5}, 1);
  const TransferFunction tf = random_tf(17, 2);
  double max_err = 0;
  for (const CameraCase& cam : kCameras) {
    SCOPED_TRACE("azimuth " + std::to_string(cam.azimuth) + " elevation " + std::to_string(cam.elevation));
    compare(vol, tf, {0.1, 0.9}, settings(13, 9, cam), 0, &max_err);  // 9 rows: one past the 8x8 tile
  }
  std::printf("max |GPU - CPU| over the cameras: %.3g\n", max_err);
}

TEST_F(RenderGpu, MatchesCpuReferenceWithNaNsAndASplitField) {
  // 3 buffers of 500 voxels: trilinear corners of one sample fall into different chunks.
  const Volume vol = test_volume({13, 11, 9}, {1.0, 1.0, 1.0}, 3, 29);
  const TransferFunction tf = random_tf(8, 4);
  for (const CameraCase& cam : {CameraCase{30, 20}, CameraCase{0, 90}, CameraCase{0, 0}}) {
    SCOPED_TRACE("elevation " + std::to_string(cam.elevation));
    compare(vol, tf, {0.0, 1.0}, settings(17, 16, cam), 500);
  }
}

TEST_F(RenderGpu, MatchesCpuReferenceWhenRaysTerminateEarly) {
  // Opaque enough that most rays stop at opacity 0.99 well before leaving the box.
  const Volume vol = test_volume({16, 16, 16}, {1.0, 1.0, 1.0}, 5);
  TransferFunction tf = random_tf(12, 6);
  for (auto& e : tf.rgba) e[3] = 0.5 + 0.5 * e[3];
  RenderSettings s = settings(15, 15, {30, 20}, 60.0);
  const CpuRender cpu = render_cpu(vol, tf, {0, 1}, s);
  size_t stopped = 0;
  for (size_t p = 0; p < cpu.stop.size(); ++p) stopped += cpu.rgba[4 * p + 3] >= 0.99;
  EXPECT_GT(stopped, cpu.stop.size() / 4) << "the case does not exercise early termination";
  compare(vol, tf, {0, 1}, s);
}

TEST_F(RenderGpu, MatchesCpuReferenceOnDegenerateGridsAndImages) {
  const TransferFunction tf = random_tf(5, 7);
  compare(test_volume({1, 1, 1}, {1, 1, 1}, 8), tf, {0, 1}, settings(9, 9, {30, 20}, 20.0));
  compare(test_volume({1, 9, 4}, {1, 1, 1}, 9), tf, {0, 1}, settings(8, 9, {90, 10}, 20.0));
  compare(test_volume({6, 5, 4}, {1, 1, 1}, 10), tf, {0, 1}, settings(1, 1, {30, 20}, 20.0));
}

TEST_F(RenderGpu, FullyNaNFieldIsTransparent) {
  Volume vol = test_volume({6, 6, 6}, {1, 1, 1}, 11);
  std::fill(vol.values.begin(), vol.values.end(), NAN);
  const RenderedImage img = render_volume(ctx(), vol, random_tf(4, 12), {0, 1}, settings(9, 9, {30, 20}));
  for (float v : img.rgba) ASSERT_EQ(v, 0.0f);
  EXPECT_GT(img.samples(), 0u) << "rays still march (and count) the empty samples";
}

TEST_F(RenderGpu, InverseMarchRecoversTheStartState) {
  // What DiffDVR's backward pass does: from the final (C, T), undo sample k_stop-1 .. 0 with the
  // same positions and colours. Float round-off of <= ~150 steps of one division and one
  // multiply-subtract each bounds the recovered state's error well below 1e-4.
  const Volume vol = test_volume({16, 12, 10}, {1.0, 1.0, 1.5}, 13, 31);
  TransferFunction tf = random_tf(16, 14);
  const RenderSettings s = settings(16, 12, {40, 25}, 40.0);
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing);
  DeviceField field(ctx(), vol.values, "inverse field", 700);
  Buffer tf_buf = upload_tf(ctx(), tf, "inverse TF");
  const MarchConstants march = march_constants(s, geo);
  const gpu::RenderView view = make_render_view(orbit_frame(s.camera, geo, s.width, s.height));
  const gpu::RenderPush push =
      make_render_push(geo, march, make_mapping({0, 1}, uint32_t(tf.size())), field, s.width, s.height, 1);
  Buffer views = make_buffer<gpu::RenderView>(ctx(), std::span(&view, 1), "views");
  const uint64_t pixels = uint64_t(s.width) * s.height;
  Buffer image(ctx(), pixels * 16, MemoryUsage::Device, "image");
  Buffer stop(ctx(), pixels * 4, MemoryUsage::Device, "stop");
  RenderImageKernel kernel(ctx(), uint32_t(field.chunk_count()), TFM_RENDER_MODE_INVERSE_CHECK);
  CommandBatch batch(ctx());
  kernel.record(batch, field, tf_buf, views, push, image, stop, 0, s.height);
  batch.submit_and_wait();
  std::vector<float> state(pixels * 4);
  std::vector<uint32_t> k_stop(pixels);
  readback(ctx(), image, state.data(), pixels * 16);
  readback(ctx(), stop, k_stop.data(), pixels * 4);
  // The forward state it started from, to make sure rays were opaque enough to matter.
  const CpuRender cpu = render_cpu(vol, tf, {0, 1}, s);
  double max_opacity = 0, max_err = 0;
  for (size_t p = 0; p < pixels; ++p) {
    max_opacity = std::max(max_opacity, cpu.rgba[4 * p + 3]);
    for (int c = 0; c < 4; ++c) {
      max_err = std::max(max_err, double(std::abs(state[4 * p + c])));
      ASSERT_LE(std::abs(state[4 * p + c]), 1e-4) << "pixel " << p << " channel " << c << " after " << k_stop[p]
                                                  << " inverse steps";
    }
  }
  EXPECT_GT(max_opacity, 0.99) << "no ray reached the termination opacity";
  std::printf("max |recovered start state| = %.3g\n", max_err);
}

}  // namespace
}  // namespace tfm
