// `--weights visibility` end to end on the paper's synthetic cube (normal-equations, qp, cgls): weighting each voxel's
// equation by how much the reference renderings see it recovers most of what DiffDVR gains over
// plain least squares (the hidden inner cube no longer pulls the colours), at the cost of one
// pass over the voxels per camera; the reported voxel losses stay the unweighted ones.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "cube_case.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

// 24^3: rays cross enough voxels for the inner cube to be clearly hidden; pictures of 96^2.
constexpr uint64_t kSize = 24;
constexpr uint32_t kPicture = 96;

using VisibilityWeightedSolvers = test::GpuTest;

TEST_F(VisibilityWeightedSolvers, CubeImagesGainOverPlainLeastSquares) {
  const test::CubeCase c(kSize);
  const OptimizeResult plain = c.fit(ctx(), "normal-equations");
  const double plain_psnr = c.image_psnr(ctx(), plain.tf, kPicture);
  EXPECT_EQ(plain.details["weights"], "none");
  TransferFunction normal_equations_tf;
  for (const char* solver : {"normal-equations", "qp", "cgls"}) {
    SCOPED_TRACE(solver);
    const OptimizeResult weighted = c.fit(ctx(), solver, {{"weights", "visibility"}});
    const double psnr = c.image_psnr(ctx(), weighted.tf, kPicture);
    std::printf("cube 24^3, %s: PSNR plain %.2f dB, visibility-weighted %.2f dB\n", solver, plain_psnr, psnr);
    EXPECT_GT(psnr, plain_psnr + 5.0);
    EXPECT_EQ(weighted.details["weights"], "visibility");
    EXPECT_EQ(weighted.details["weight_views"], DetailValue(8u));
    bool weight_phase = false;
    for (const PhaseTime& p : weighted.phases) weight_phase = weight_phase || p.name == "visibility weights";
    EXPECT_TRUE(weight_phase);
    // The losses reported are the plain voxel losses of the weighted fit's TF: the weighted fit
    // is worse on them than the plain one, which minimizes exactly them.
    EXPECT_EQ(weighted.before.rmse(), plain.before.rmse());
    EXPECT_GT(weighted.after.rmse(), plain.after.rmse());
    // CGLS, matrix-free over the weighted rows, reaches the weighted system's solution.
    if (std::string(solver) == "normal-equations") normal_equations_tf = weighted.tf;
    if (std::string(solver) == "cgls") {
      double worst = 0.0;
      for (size_t j = 0; j < weighted.tf.size(); ++j)
        for (int k = 0; k < 4; ++k) worst = std::max(worst, std::abs(weighted.tf.rgba[j][k] - normal_equations_tf.rgba[j][k]));
      EXPECT_LT(worst, 1e-3) << "weighted CGLS against the weighted normal equations";
    }
  }
  // Random cameras, a seed: another camera set, still a gain.
  const OptimizeResult random = c.fit(ctx(), "normal-equations",
                                    {{"weights", "visibility"}, {"cameras", "random"}, {"seed", "4"}, {"weight-views", "6"}});
  EXPECT_GT(c.image_psnr(ctx(), random.tf, kPicture), plain_psnr + 3.0);
}

TEST_F(VisibilityWeightedSolvers, OptionsAreCheckedAndOnlyWhereTheyApply) {
  const test::CubeCase c(kSize);
  EXPECT_THROW(c.fit(ctx(), "normal-equations", {{"weights", "brightness"}}), std::runtime_error);
  EXPECT_THROW(c.fit(ctx(), "normal-equations", {{"weights", "visibility"}, {"weight-views", "0"}}), std::runtime_error);
  EXPECT_THROW(c.fit(ctx(), "gradient-descent", {{"weights", "visibility"}}), std::runtime_error);
}

}  // namespace
}  // namespace tfm
