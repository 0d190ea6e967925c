// `tfmatch demo` as a newcomer runs it: the default pair's residual after optimization lies in the
// regions that really changed (its ground-truth mask, checked against a residual map computed by
// `tfmatch residual` from the written files), and the folds case and its refusals.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/model/synthetic.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::run_cli;
using test::TempDir;

template <class T>
std::vector<T> read_values(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  std::vector<T> v(bytes.size() / sizeof(T));
  std::memcpy(v.data(), bytes.data(), v.size() * sizeof(T));
  return v;
}

TEST(DemoCli, TheResidualAfterOptimizationFindsTheChangedRegions) {
  TempDir dir;
  const fs::path out = dir.path / "demo";
  const auto r = run_cli("demo --out " + out.string() + " --width 96 --height 96");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto mask = read_values<uint8_t>(out / "difference_mask_96x96x96_uint8.raw");
  ASSERT_EQ(mask.size(), 96u * 96u * 96u);
  // The mask holds the whole sphere of another pattern and the moved blob: a few percent of the box.
  const Volume grid = synthetic_reference(96, 96, 96);
  const Sphere s = synthetic_difference_region(grid);
  size_t set = 0, sphere = 0, sphere_set = 0;
  for (uint64_t z = 0; z < 96; ++z)
    for (uint64_t y = 0; y < 96; ++y)
      for (uint64_t x = 0; x < 96; ++x) {
        const size_t i = (z * 96 + y) * 96 + x;
        set += mask[i];
        if (std::pow(x - s.cx, 2) + std::pow(y - s.cy, 2) + std::pow(z - s.cz, 2) < s.r * s.r) ++sphere, sphere_set += mask[i];
      }
  EXPECT_EQ(sphere_set, sphere);
  EXPECT_GT(set, sphere) << "the moved blob adds voxels of its own";
  EXPECT_LT(double(set) / mask.size(), 0.2);

  // The residual map of the written fields and TFs, recomputed by `tfmatch residual`: at least 80 %
  // of its sum inside the changed regions, as the report says.
  const auto res = run_cli("residual --ref " + (out / "reference_96x96x96_float32.raw").string() + " --ref-tf " +
                           (out / "reference_tf.json").string() + " --field " +
                           (out / "field_96x96x96_float32.raw").string() + " --field-tf " +
                           (out / "optimized_tf.json").string() + " --out " + (dir.path / "res.raw").string());
  ASSERT_EQ(res.exit_code, 0) << res.output;
  const auto residual = read_values<float>(dir.path / "res.raw");
  ASSERT_EQ(residual.size(), mask.size());
  double inside = 0, all = 0;
  for (size_t i = 0; i < residual.size(); ++i) {
    all += residual[i];
    if (mask[i]) inside += residual[i];
  }
  const double fraction = inside / all;
  EXPECT_GE(fraction, 0.80);
  const auto metrics = nlohmann::json::parse(std::ifstream(out / "metrics.json"));
  // The robust fit by default: least absolute deviations by IRLS, converged.
  EXPECT_EQ(metrics["optimize"]["solver"], "irls");
  EXPECT_TRUE(metrics["optimize"]["details"]["converged"].get<bool>());
  const auto& reported = metrics["residual"]["fraction_inside_changed_regions"];
  EXPECT_NEAR(reported["optimized_tf"].get<double>(), fraction, 1e-4);
  EXPECT_LT(reported["reference_tf"].get<double>(), 0.5) << "before, the remap's mismatch is everywhere";
  EXPECT_NE(r.output.find("residual inside the changed regions: "), std::string::npos) << r.output;
  std::ifstream page(out / "index.html");
  const std::string html((std::istreambuf_iterator<char>(page)), {});
  EXPECT_NE(html.find("Residual inside the changed regions"), std::string::npos);
}

TEST(DemoCli, FoldsCaseHasNoMaskAndRefusesTheEnsemble) {
  TempDir dir;
  const fs::path out = dir.path / "folds";
  const auto r = run_cli("demo --case folds --size 16 --out " + out.string() + " --width 24 --height 24");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("non-monotone"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out / "difference_mask_16x16x16_uint8.raw"));
  const auto metrics = nlohmann::json::parse(std::ifstream(out / "metrics.json"));
  EXPECT_FALSE(metrics["residual"].contains("fraction_inside_changed_regions"));
  EXPECT_EQ(metrics["optimize"]["solver"], "normal-equations");

  const auto both = run_cli("demo --case folds --ensemble --out " + (dir.path / "x").string());
  EXPECT_EQ(both.exit_code, 2) << both.output;
  EXPECT_NE(both.output.find("--ensemble"), std::string::npos) << both.output;
  const auto bad = run_cli("demo --case spheres --out " + (dir.path / "x").string());
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
  EXPECT_NE(bad.output.find("changes"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(dir.path / "x"));
}

}  // namespace
}  // namespace tfm
