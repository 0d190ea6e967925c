// tools/torch_peer.py, the PyTorch peer of the GPU benchmarks: on the CPU where PyTorch is installed
// (Debian's python3-torch; skipped otherwise), its --check against double-precision NumPy passes
// and it writes every figure the README's GPU tables take from it.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <string>

#include "cli_runner.h"
#include "tfmatch/io/json.h"

namespace tfm {
namespace {

// A Python that has NumPy and PyTorch: the one on PATH, else Debian's (a PATH may put another
// first, such as pyenv's); empty when neither has them.
std::string python_with_torch() {
  for (const char* python : {"python3", "/usr/bin/python3"})
    if (std::system((std::string(python) + " -c 'import numpy, torch' >/dev/null 2>&1").c_str()) == 0) return python;
  return "";
}

TEST(TorchPeer, ChecksItselfAndReportsEveryFigure) {
  const std::string python = python_with_torch();
  if (python.empty())
    GTEST_SKIP() << "no python3 with numpy and torch (Debian python3-torch); the peer runs on GPU machines";
  test::TempDir dir;
  const std::string json = dir / "torch.json";
  const std::string cmd = python + " " + TFMATCH_SOURCE_DIR + "/tools/torch_peer.py --device cpu --check "
                          "--voxels 20011 --correlation 10x3001,40x301 --repeats 1 --json " + json + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json));
  EXPECT_TRUE(j["check"]["passed"].get<bool>()) << j.dump(2);
  EXPECT_LT(j["check"]["assembly_max_relative"].get<double>(), 1e-4);
  for (const char* key : {"read_bytes_per_s", "assemble_voxels_per_s"}) EXPECT_GT(j[key].get<double>(), 0.0) << key;
  ASSERT_EQ(j["correlation"].size(), 4u);  // pearson and spearman at each size
  for (const auto& c : j["correlation"]) {
    EXPECT_GT(c["voxels_per_s"].get<double>(), 0.0);
    EXPECT_NEAR(c["voxels_per_s"].get<double>(), c["voxels"].get<double>() / (c["ms"].get<double>() * 1e-3),
                1e-6 * c["voxels_per_s"].get<double>());
  }
}

}  // namespace
}  // namespace tfm
