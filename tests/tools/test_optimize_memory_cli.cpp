// `tfmatch optimize` under --max-memory: what comes after the load is counted before the work. The
// Vulkan device that starts while the fields are read, and a report's fields, residual maps and
// pictures, are refused before the solve with a message that names them, and nothing is written.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <string>

#include "cli_runner.h"
#include "slab_test_files.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::run_cli;

class OptimizeMemoryCli : public ::testing::Test {
 protected:
  // A pair of `side`^3 float32 fields.
  void write_pair(uint64_t side) {
    ref = slab_test::write_raw(dir.path(), "ref", slab_test::test_field({side, side, side}, 0)).string();
    field = slab_test::write_raw(dir.path(), "field", slab_test::test_field({side, side, side}, 4)).string();
  }
  std::string args() const {
    return "optimize --stream off --ref " + ref + " --ref-tf viridis --field " + field + " --out " +
           (dir / "tf.json").string();
  }
  formats_test::TempDir dir;
  std::string ref, field;
};

// Two 8 MiB fields fit 60 MiB beside tfmatch's own ~12 MiB, but not beside the device's ~62 MiB
// (lavapipe), which starts meanwhile: the load's check saw 12 MiB in use, passed, and the run
// went on to ~100 MiB.
TEST_F(OptimizeMemoryCli, TheStartingDeviceCountsInTheLoadCheck) {
  write_pair(128);
  const test::CliResult r = run_cli("--max-memory 60M " + args());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("reading both"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("set aside for the Vulkan device starting"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "tf.json"));
}

// The report's needs (here 5 volumes of 27 MiB where device memory is the host's) are checked
// before the solve: the run used to solve, then fail in the report blaming a 5.75 MiB read-back.
TEST_F(OptimizeMemoryCli, AReportThatCannotFitIsRefusedBeforeTheSolve) {
  write_pair(192);
  const test::CliResult r = run_cli("--max-memory 230M " + args() + " --report " + (dir / "report").string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("report: both fields and a residual map on the device, two residual maps and the pictures"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("reading back"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("assembl"), std::string::npos) << r.output;  // no solver progress
  EXPECT_LT(r.peak_rss_bytes, uint64_t(230) << 20) << "peak RSS " << r.peak_rss_bytes;
  EXPECT_FALSE(fs::exists(dir / "tf.json"));
  EXPECT_FALSE(fs::exists(dir / "report"));
}

// DiffDVR's images grow with the image size and the views: the reference images of its view
// pool (32 views of 2048 x 2048: 2 GiB) and the per-ray states of the views it renders at once
// are checked before they are made, refused naming them, and quickly (both were made unchecked:
// two 256^3 fields held 425 MiB at a budget of 150 MiB).
TEST_F(OptimizeMemoryCli, DiffDvrImagesAreCheckedBeforeTheyAreMade) {
  write_pair(24);
  const auto t0 = std::chrono::steady_clock::now();
  const std::string diffdvr = " --solver diffdvr --iterations 1 --image-size 2048";
  test::CliResult r = run_cli("--max-memory 1G " + args() + diffdvr);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("diffdvr: the reference images of a pool of 32 views of 2048x2048: needs"), std::string::npos)
      << r.output;
  r = run_cli("--max-memory 150M " + args() + diffdvr + " --view-pool 0");  // new cameras every iteration: no pool
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("diffdvr: the ray states of "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" of 2048x2048: needs "), std::string::npos) << r.output;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(60));
  EXPECT_FALSE(fs::exists(dir / "tf.json"));
}

}  // namespace
}  // namespace tfm
