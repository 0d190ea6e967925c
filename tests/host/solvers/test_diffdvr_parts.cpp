// The host parts of DiffDVR: camera sampling, projected Adam, exact fixed-point totals, the
// smoothness prior's effect, the loss-curve plot.
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include <glm/glm.hpp>
#include <gtest/gtest.h>

#include "tfmatch/kernels/diffdvr.h"
#include "tfmatch/model/cameras.h"
#include "tfmatch/reference/diffdvr_cpu.h"
#include "tfmatch/report/font.h"
#include "tfmatch/report/loss_plot.h"
#include "tfmatch/solvers/adam.h"

namespace tfm {
namespace {

glm::dvec3 direction(const OrbitCamera& c) {
  const double d = std::numbers::pi / 180.0, az = c.azimuth_deg * d, el = c.elevation_deg * d;
  return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

TEST(DiffDvrCameras, RandomPosesAreSeededAndUniformOnTheSphere) {
  OrbitCamera base;
  base.distance = 2.7;
  base.fov_deg = 25;
  RandomCameras a(42, base), b(42, base), c(43, base);
  const auto pa = a.next(4000), pb = b.next(4000), pc = c.next(4000);
  glm::dvec3 mean(0.0);
  double upper = 0;
  for (size_t i = 0; i < pa.size(); ++i) {
    ASSERT_EQ(pa[i].azimuth_deg, pb[i].azimuth_deg);
    ASSERT_EQ(pa[i].elevation_deg, pb[i].elevation_deg);
    ASSERT_EQ(pa[i].distance, 2.7);
    ASSERT_EQ(pa[i].fov_deg, 25);
    ASSERT_GE(pa[i].elevation_deg, -90.0);
    ASSERT_LE(pa[i].elevation_deg, 90.0);
    mean += direction(pa[i]);
    upper += direction(pa[i]).z > 0.5;  // a cap of 1/4 of the sphere's area
  }
  mean /= double(pa.size());
  // Uniform directions: each mean component has standard deviation sqrt(1/3 / 4000) = 0.009.
  EXPECT_LT(glm::length(mean), 0.05);
  EXPECT_NEAR(upper / pa.size(), 0.25, 0.03);  // binomial sd 0.007
  EXPECT_NE(pa[0].azimuth_deg, pc[0].azimuth_deg) << "another seed, other poses";
  // The stream continues: the next batch differs from the first.
  EXPECT_NE(a.next(1)[0].azimuth_deg, pa[0].azimuth_deg);
}

TEST(DiffDvrCameras, FibonacciSphereCoversBothPolesEvenly) {
  for (uint32_t n : {1u, 2u, 8u, 13u, 127u}) {
    const auto cams = fibonacci_cameras(n, OrbitCamera{});
    ASSERT_EQ(cams.size(), n);
    glm::dvec3 mean(0.0);
    for (const auto& c : cams) mean += direction(c);
    // Equal-area bands: the z components are symmetric about 0, so they cancel exactly.
    EXPECT_NEAR(mean.z, 0.0, 1e-9) << n;
    if (n >= 8) EXPECT_LT(glm::length(mean) / n, 0.1) << n;
  }
  const auto cams = fibonacci_cameras(200, OrbitCamera{});
  double closest = 1e9;  // no two views nearly coincide
  for (size_t i = 0; i < cams.size(); ++i)
    for (size_t k = i + 1; k < cams.size(); ++k)
      closest = std::min(closest, glm::length(direction(cams[i]) - direction(cams[k])));
  EXPECT_GT(closest, 0.1);  // ideal spacing for 200 points is ~0.25
}

TEST(DiffDvrAdam, StepsByTheRateThenConvergesInsideTheBox) {
  AdamOptions o;
  o.learning_rate = 0.1;
  Adam adam(3, o);
  std::vector<double> x{0.5, 0.5, 0.05};
  // The first step of Adam moves every coordinate by lr against the gradient's sign.
  adam.step(x, std::vector<double>{2.0, -1e-3, 1.0});
  EXPECT_NEAR(x[0], 0.4, 1e-6);
  EXPECT_NEAR(x[1], 0.6, 1e-6);
  EXPECT_EQ(x[2], 0.0) << "projected onto [0, 1]";
  // Minimize (x0 - 0.3)^2 + (x1 - 1.7)^2 + (x2 + 1)^2 over the box: optimum (0.3, 1, 0).
  for (int i = 0; i < 500; ++i) adam.step(x, std::vector<double>{2 * (x[0] - 0.3), 2 * (x[1] - 1.7), 2 * (x[2] + 1)});
  EXPECT_NEAR(x[0], 0.3, 1e-3);
  EXPECT_EQ(x[1], 1.0);
  EXPECT_EQ(x[2], 0.0);
  EXPECT_THROW(Adam(2, AdamOptions{.learning_rate = 0}), std::invalid_argument);
  EXPECT_THROW(adam.step(x, std::vector<double>{1.0}), std::invalid_argument);
}

TEST(DiffDvrFixedPoint, TotalsAreExactAndIndependentOfTheSplit) {
  // 32.32 two's complement words of a few signed values, as the backward kernel writes them.
  auto words = [](std::vector<double> values) {
    std::vector<uint32_t> w;
    for (double v : values) {
      const int64_t bits = std::llround(v * 4294967296.0);
      w.push_back(uint32_t(uint64_t(bits)));
      w.push_back(uint32_t(uint64_t(bits) >> 32));
    }
    return w;
  };
  const std::vector<uint32_t> a = words({-1.5, 3.25, -0.000001, 2147483000.0});
  const std::vector<uint32_t> b = words({0.75, -3.25, 0.000002, 600.5});
  FixedPointTotals both(4), first(4);
  both.add(a.data());
  both.add(b.data());
  first.add(a.data());
  const std::vector<double> t = both.values(), f = first.values();
  EXPECT_EQ(t[0], -0.75);
  EXPECT_EQ(t[1], 0.0);
  EXPECT_NEAR(t[2], 1e-6, 1e-9);  // 2^-32 resolution
  EXPECT_EQ(t[3], 2147483600.5);
  EXPECT_EQ(f[0], -1.5);
  first.add(a.data());
  first.add(a.data());
  EXPECT_EQ(first.values()[3], 3.0 * 2147483000.0) << "totals beyond one accumulator's 2^31 range stay exact";
  // The same total split differently gives the same bits.
  const std::vector<uint32_t> c = words({-0.75, 0.0, 0.000001, 2147483600.5});
  FixedPointTotals once(4);
  once.add(c.data());
  for (int k = 0; k < 4; ++k) EXPECT_EQ(once.values()[k], t[k]) << k;
}

TEST(DiffDvrLoss, ParsesNamesAndMeasuresImages) {
  EXPECT_EQ(parse_image_loss("l1"), ImageLoss::L1);
  EXPECT_EQ(parse_image_loss("l2"), ImageLoss::L2);
  EXPECT_THROW(parse_image_loss("L2"), std::runtime_error);
  const std::vector<double> x{0.5, 0.25, 0, 1}, r{0.25, 0.25, 0.5, 0.5};
  EXPECT_DOUBLE_EQ(image_loss(x, r, ImageLoss::L2), 0.0625 + 0.25 + 0.25);
  EXPECT_DOUBLE_EQ(image_loss(x, r, ImageLoss::L1), 0.25 + 0.5 + 0.5);
}

TEST(DiffDvrPlot, DrawsTheCurveAndRejectsEmptyInput) {
  const std::vector<double> curve{0.1, 0.05, 0.02, 0.021, 0.01, 0.0};
  const Image img = plot_loss_curve(curve, 300, 120, "loss");
  ASSERT_EQ(img.width, 300u);
  ASSERT_EQ(img.height, 120u);
  size_t red = 0;
  for (size_t p = 0; p < size_t(img.width) * img.height; ++p)
    red += img.rgb[3 * p] > 150 && img.rgb[3 * p + 1] < 120 && img.rgb[3 * p + 2] < 120;
  EXPECT_GT(red, 100u) << "the curve is drawn";
  EXPECT_THROW(plot_loss_curve({}, 300, 120, "x"), std::invalid_argument);
  EXPECT_THROW(plot_loss_curve(curve, 50, 20, "x"), std::invalid_argument);
  OptimizeResult r;
  r.solver = "normal-equations";
  EXPECT_TRUE(solver_report_figures(r).empty());
  r.solver = "diffdvr";
  r.details["loss_curve"] = curve;
  // Drawn in the reports' font even before a report installs it (the CLI draws it first: the
  // bitmap font's "l2" read "12").
  set_text_face(nullptr);
  ASSERT_EQ(solver_report_figures(r).size(), 1u);
  if (!report_font_file().empty()) {
    EXPECT_NE(text_face(), nullptr) << "the loss plot was drawn in the bitmap font";
  }
  EXPECT_EQ(solver_report_figures(r)[0].file, "loss.png");
}

}  // namespace
}  // namespace tfm
