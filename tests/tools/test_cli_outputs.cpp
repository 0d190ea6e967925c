// The command line's outputs, checked before any work (issue 15, item 2 and the report case of
// item 5): one file for two outputs, an output that is an input (by name, symbolic or hard link),
// a read-only target, a --report that is a file, for every command that writes; reports into new
// nested directories; and the messages of item 5 (render size, ranges beyond float32 or infinite,
// negative --dims, the residual of a field with itself). Each runs the real program.
#include <gtest/gtest.h>

#include <fstream>
#include <limits>

#include "cli_runner.h"
#include "tfmatch/io/json.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::files_under;
using test::run_cli;
using test::TempDir;
using test::write_floats;

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

class CliOutputs : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<float> ref(512), field(512);
    for (size_t i = 0; i < ref.size(); ++i) {
      ref[i] = float(i % 23) / 22.0f;
      field[i] = 5.0f + 3.0f * ref[i] * ref[i];
    }
    write_floats(dir / "ref_8x8x8_float32.raw", ref);
    write_floats(dir / "field_8x8x8_float32.raw", field);
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
  }
  std::string inputs() const {
    return "--ref " + dir / "ref_8x8x8_float32.raw" + " --field " + dir / "field_8x8x8_float32.raw" + " --ref-tf " +
           dir / "tf.json" + " --tf-size 16";
  }
  // Runs `args`, expects a failure whose output holds every needle, that the solve never started
  // (TFMATCH_TRACE_PHASES shows the phases reached) and that the directory holds `left` only.
  void expect_refused(const std::string& args, std::initializer_list<std::string> needles) {
    const std::vector<std::string> before = files_under(dir.path);
    test::CliProcess p(args, {{"TFMATCH_TRACE_PHASES", "1"}});
    // Refused before any work: a command that ran instead (a whole benchmark) fails by the deadline.
    const test::CliResult r = p.finish(test::kQuickCliTimeout);
    EXPECT_FALSE(r.timed_out) << args << "\n" << r.output;
    EXPECT_NE(r.exit_code, 0) << r.output;
    for (const std::string& n : needles) EXPECT_NE(r.output.find(n), std::string::npos) << "no '" << n << "' in\n" << r.output;
    EXPECT_EQ(r.output.find("phase load"), std::string::npos) << "work started before the check:\n" << r.output;
    EXPECT_EQ(files_under(dir.path), before) << r.output;
  }
  TempDir dir;
};

TEST_F(CliOutputs, OneFileForTwoOutputsIsRefused) {
  expect_refused("optimize " + inputs() + " --out " + dir / "x.json" + " --json " + dir / "x.json",
                 {"--json", "same file as --out", "x.json"});
  expect_refused("optimize " + inputs() + " --out " + dir / "t.json" + " --json " + dir / "r/metrics.json" + " --report " +
                     dir / "r",
                 {"--json", "metrics.json", "same file as --report"});
  expect_refused("residual --ref " + dir / "ref_8x8x8_float32.raw" + " --field " + dir / "field_8x8x8_float32.raw" +
                     " --ref-tf " + dir / "tf.json" + " --field-tf " + dir / "tf.json" + " --out " + dir / "m.png" +
                     " --image " + dir / "m.png",
                 {"--out", "m.png", "would hold a field"});  // one name cannot be both a field and an image
}

TEST_F(CliOutputs, AnOutputThatIsAnInputIsRefused) {
  const std::string ref = dir / "ref_8x8x8_float32.raw", tf = dir / "tf.json";
  const std::string ref_bytes = read_bytes(ref), tf_bytes = read_bytes(tf);
  expect_refused("residual --ref " + ref + " --field " + dir / "field_8x8x8_float32.raw" + " --ref-tf " + tf +
                     " --field-tf " + tf + " --out " + ref,
                 {"--out", "same file as --ref", "destroy"});
  expect_refused("optimize " + inputs() + " --out " + tf, {"--out", "same file as --ref-tf"});
  // The same file through a symbolic link and a hard link.
  fs::create_symlink(tf, dir / "link.json");
  expect_refused("optimize " + inputs() + " --out " + dir / "link.json", {"same file as --ref-tf"});
  fs::create_hard_link(tf, dir / "hard.json");
  expect_refused("optimize " + inputs() + " --out " + dir / "hard.json", {"same file as --ref-tf"});
  // convert-volume A.vti A.vti.
  test::CliResult r = run_cli("convert-volume " + ref + " " + dir / "a.vti");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string vti_bytes = read_bytes(dir / "a.vti");
  expect_refused("convert-volume " + dir / "a.vti" + " " + dir / "a.vti", {"output", "same file as input 1"});
  EXPECT_EQ(read_bytes(ref), ref_bytes);
  EXPECT_EQ(read_bytes(tf), tf_bytes);
  EXPECT_EQ(read_bytes(dir / "a.vti"), vti_bytes);
}

TEST_F(CliOutputs, ReadOnlyTargetsAndBadDirectoriesAreRefused) {
  std::ofstream(dir / "ro.json") << "keep";
  fs::permissions(dir / "ro.json", fs::perms::owner_read);
  expect_refused("optimize " + inputs() + " --out " + dir / "ro.json", {"--out", "ro.json", "read-only"});
  EXPECT_EQ(read_bytes(dir / "ro.json"), "keep");
  expect_refused("optimize " + inputs() + " --out " + dir / "nodir/x.json", {"--out", "nodir", "does not exist"});
  // --report naming a file used to fail after the solve, with --out already written.
  std::ofstream(dir / "report.txt") << "a file";
  expect_refused("optimize " + inputs() + " --out " + dir / "x.json" + " --report " + dir / "report.txt",
                 {"--report", "report.txt", "not a directory"});
  fs::create_symlink(dir / "ref_8x8x8_float32.raw", dir / "volume.png");
  expect_refused("render --volume " + dir / "volume.png" + " --tf " + dir / "tf.json" + " --out " + dir / "volume.png",
                 {"--out", "same file as --volume"});
}

TEST_F(CliOutputs, ReportGoesIntoANewNestedDirectoryWhole) {
  const std::string report = dir / "new/a/b";
  test::CliResult r = run_cli("optimize " + inputs() + " --out " + dir / "t.json" + " --report " + report +
                              " --width 24 --height 24");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(fs::path(report) / "index.html"));
  EXPECT_TRUE(fs::exists(dir / "t.json"));
  // Nothing hidden (temporary files, staged directories) is left anywhere.
  for (const std::string& f : files_under(dir.path)) EXPECT_EQ(f.find("/."), std::string::npos) << f;
  for (const std::string& f : files_under(dir.path)) EXPECT_NE(f[0], '.') << f;
}

// A file name that is not UTF-8 (Latin-1 "é": byte E9) is written into the JSON files as U+FFFD:
// JSON must be UTF-8, and a strict writer threw at the end of the run and lost every output.
TEST_F(CliOutputs, FileNamesThatAreNotUtf8StillGiveEveryOutput) {
  const std::string latin1 = "lat\xe9_8x8x8_float32.raw";
  fs::copy_file(dir / "field_8x8x8_float32.raw", dir / latin1);
  const std::string field = dir / latin1;
  for (const std::string& series : std::vector<std::string>{"", " --field " + dir / "field_8x8x8_float32.raw"}) {
    const fs::path report = dir / (series.empty() ? "rep" : "rep_series");
    const fs::path json = dir / (series.empty() ? "one.json" : "series.json");
    const fs::path tf = dir / (series.empty() ? "t.json" : "s.json");
    test::CliResult r = run_cli("optimize --ref " + dir / "ref_8x8x8_float32.raw" + " --field " + field + series +
                                " --ref-tf " + dir / "tf.json" + " --tf-size 16 --out " + tf.string() + " --report " +
                                report.string() + " --json " + json.string() + " --width 24 --height 24");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(fs::exists(report / "index.html"));
    EXPECT_TRUE(nlohmann::json::accept(read_bytes(json)));
    const std::string page_json = read_bytes(report / (series.empty() ? "metrics.json" : "series.json"));
    EXPECT_NE(page_json.find("lat\xef\xbf\xbd_8x8x8"), std::string::npos) << page_json;  // U+FFFD
    EXPECT_TRUE(nlohmann::json::accept(page_json));
    // Both pages say when and on which device and driver they were made.
    EXPECT_TRUE(nlohmann::json::parse(page_json)["made"].contains("driver")) << page_json;
    EXPECT_NE(read_bytes(report / "index.html").find("Made 20"), std::string::npos);
  }
}

// Every other command that writes files declares them in the same check (FilePlan) before any
// work: correlate and the benchmarks, selftest, solvers, devices, convert-tf and demo; one bad
// output each, of the kinds above.
TEST_F(CliOutputs, EveryCommandThatWritesChecksItsFilesFirst) {
  for (int m = 1; m <= 3; ++m) write_floats(dir / ("m" + std::to_string(m) + "_8x8x8_float32.raw"), std::vector<float>(512, float(m)));
  const std::string members = "--members '" + dir / "m*_8x8x8_float32.raw" + "' --point 1,1,1";
  std::ofstream(dir / "ro.json") << "keep";
  fs::permissions(dir / "ro.json", fs::perms::owner_read);
  std::ofstream(dir / "afile") << "a file";
  // Names must fit their formats (.vti, .json), so one file under both takes a hard link.
  std::ofstream(dir / "x.vti") << "old";
  fs::create_hard_link(dir / "x.vti", dir / "x.json");
  expect_refused("correlate " + members + " --out " + dir / "x.vti" + " --json " + dir / "x.json",
                 {"--json", "same file as --out"});
  expect_refused("correlate " + members + " --out " + dir / "m2_8x8x8_float32.raw", {"--out", "same file as --members"});
  expect_refused("bench-correlate --quick --json " + dir / "ro.json", {"--json", "read-only"});
  expect_refused("bench --json " + dir / "nodir/b.json", {"--json", "does not exist"});
  expect_refused("bench-render --json " + dir / "ro.json", {"--json", "read-only"});
  expect_refused("bench-diffdvr --json " + dir / "nodir/b.json", {"--json", "does not exist"});
  // bench-solve takes its TF sizes from --tf-sizes.
  const std::string bench_inputs = inputs().substr(0, inputs().rfind(" --tf-size")) + " --tf-sizes 16";
  expect_refused("bench-solve " + bench_inputs + " --json " + dir / "tf.json", {"--json", "same file as --ref-tf"});
  expect_refused("selftest --json " + dir / "nodir/s.json", {"--json", "does not exist"});
  expect_refused("solvers --json " + dir / "ro.json", {"--json", "read-only"});
  expect_refused("devices --json " + dir / "afile/d.json", {"--json", "afile"});
  expect_refused("convert-tf " + dir / "tf.json" + " " + dir / "tf.json", {"output", "same file as input"});
  expect_refused("demo --out " + dir / "afile", {"--out", "not a directory"});
  // A correlate that fails after its check (a point outside the grid) writes neither output.
  const test::CliResult r = run_cli("correlate --members '" + dir / "m*_8x8x8_float32.raw" + "' --point 9,1,1 --out " +
                                    dir / "c.vti" + " --json " + dir / "c.json");
  EXPECT_FALSE(r.timed_out) << r.output;
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--point '9,1,1': index 9 along x is outside the grid 8x8x8"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "c.vti"));
  EXPECT_FALSE(fs::exists(dir / "c.json"));
  for (const std::string& f : files_under(dir.path)) EXPECT_EQ(f.find("/."), std::string::npos) << f;
}

// Item 5's messages, each saying the true problem.

// A size inside the accepted range that the device cannot hold: said before loading, with the
// largest size that fits, not a raw VK_ERROR_OUT_OF_DEVICE_MEMORY from a buffer.
TEST_F(CliOutputs, RenderSizeTheDeviceCannotHoldIsNamed) {
  test::CliResult r = run_cli("render --volume " + dir / "ref_8x8x8_float32.raw" + " --tf " + dir / "tf.json" +
                              " --out " + dir / "big.png" + " --width 16384 --height 16384");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("16384x16384 image needs a 4.00 GiB image buffer"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("at most about"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("VK_ERROR"), std::string::npos) << r.output;
  // Just over a 128 MiB limit (lavapipe's maxStorageBufferRange): sizes that round alike are
  // given in bytes too, not "128 MiB, more than ... 128 MiB".
  r = run_cli("render --volume " + dir / "ref_8x8x8_float32.raw" + " --tf " + dir / "tf.json" + " --out " +
              dir / "big.png" + " --width 4097 --height 2048");
  if (r.output.find("needs a 128 MiB") != std::string::npos) {
    EXPECT_NE(r.output.find("needs a 128 MiB (134250496 bytes) image buffer"), std::string::npos) << r.output;
  } else {
    EXPECT_EQ(r.exit_code, 0) << r.output;  // a device that binds more renders it
  }
}

// A TF file's range beyond float32: named as such, with the file, not "too narrow".
TEST_F(CliOutputs, RangeBeyondFloat32IsNamed) {
  std::ofstream(dir / "wide.json") << R"({"rgba": [[0,0,0,0],[1,1,1,1]], "range": [-1e308, 1e308]})";
  test::CliResult r = run_cli("render --volume " + dir / "ref_8x8x8_float32.raw" + " --tf " + dir / "wide.json" +
                              " --out " + dir / "w.png");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("wide.json: range -1e+308,1e+308 lies beyond float32"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("too narrow"), std::string::npos) << r.output;
}

// Infinite ends are not "empty or reversed".
TEST_F(CliOutputs, InfiniteRangeIsNamed) {
  test::CliResult r = run_cli("render --volume " + dir / "ref_8x8x8_float32.raw" + " --tf " + dir / "tf.json" +
                              " --out " + dir / "i.png" + " --range -inf,inf");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("--range: range -inf,inf: both ends must be finite numbers"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("reversed"), std::string::npos) << r.output;
}

// A negative grid size is not an overflow.
TEST_F(CliOutputs, NegativeDimsAreNamed) {
  test::CliResult r = run_cli("info " + dir / "ref_8x8x8_float32.raw" + " --dims -64,64,64 --type float32");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("expected a positive integer, got '-64'"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("overflow"), std::string::npos) << r.output;
}

// A number that is not one is a usage error naming the option, before any work, on every
// command: CLI11 alone read "" as 0, let NaN through every range (`--ridge nan` wrote a TF of
// ones with exit 0) and wrapped "-1" to 2^64 - 1 ("time 18446744073709551615 is out of range").
TEST_F(CliOutputs, EmptyNanAndNegativeNumbersAreUsageErrors) {
  const std::string out = " --out " + dir / "out.json";
  const std::string volume = " --volume " + dir / "ref_8x8x8_float32.raw" + " --tf " + dir / "tf.json" + " --out " +
                             dir / "out.png";
  const struct {
    std::string args, message;
  } cases[] = {
      {"optimize " + inputs() + out + " --solver qp --ridge nan", "--ridge: expected a number, got 'nan'"},
      {"optimize " + inputs() + out + " --smooth ''", "--smooth: expected a number, got ''"},
      {"optimize " + inputs() + out + " --ridge -1", "--ridge: expected a number >= 0, got '-1'"},
      {"render" + volume + " --azimuth ''", "--azimuth: expected a number, got ''"},
      {"render" + volume + " --elevation NaN", "--elevation: expected a number, got 'NaN'"},
      {"render" + volume + " --step nan", "--step: expected a number, got 'nan'"},
      // An infinity too (--azimuth inf failed after reading, exit 1, where nan was a usage error).
      {"render" + volume + " --azimuth inf", "--azimuth: expected a finite number, got 'inf'"},
      {"optimize " + inputs() + out + " --smooth -infinity", "--smooth: expected a finite number, got '-infinity'"},
      {"info " + dir / "ref_8x8x8_float32.raw" + " --time -1", "--time: expected a number >= 0, got '-1'"},
      {"bench --tf-sizes 16,-4", "--tf-sizes: Value -4 not in range 2 to 1048576"},
      // not "Value  not in range 2 to 65536"
      {"optimize " + inputs() + out + " --tf-size ''", "--tf-size: expected a number, got ''"},
      {"render" + volume + " --width ' '", "--width: expected a number, got ' '"},
      {"correlate --members " + dir / "ref_8x8x8_float32.raw" + " --point 1,1,1 --time -2 --out " + dir / "out.vti",
       "--time: expected a number >= 0, got '-2'"},
      {"view --demo --k 0", "--k: expected a number > 0, got '0'"},
      // A range whose 1 / (hi - lo) leaves float32: named as the option's (it failed after the
      // fields were read, as "range 0,1e-45 cannot be mapped ...").
      {"residual --ref " + dir / "ref_8x8x8_float32.raw" + " --ref-tf " + dir / "tf.json" + " --field " +
           dir / "field_8x8x8_float32.raw" + " --field-tf " + dir / "tf.json" + " --out " + dir / "out.vti" +
           " --image " + dir / "out.png" + " --display-range 0,1e-45",
       "--display-range: range 0,1e-45 is too narrow"},
  };
  for (const auto& c : cases) {
    const test::CliResult r = run_cli(c.args, test::kQuickCliTimeout);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.args << "\n" << r.output;
    EXPECT_EQ(r.output.find("1797693"), std::string::npos) << "DBL_MAX printed in full:\n" << r.output;
    for (const char* name : {"out.json", "out.png", "out.vti"}) EXPECT_FALSE(fs::exists(dir.path / name)) << c.args;
  }
}

// A second field with data in four voxels leaves most TF entries touched by no voxel: every
// voxel solver leaves them at 0 and says so once (normal-equations in its own words, "M is
// singular"), the streamed and the shared-TF paths too; --smooth fills them, so no warning. The
// solvers but normal-equations had said nothing.
TEST_F(CliOutputs, EveryVoxelSolverSaysWhichEntriesNoVoxelTouches) {
  std::vector<float> sparse(512, std::numeric_limits<float>::quiet_NaN());
  sparse[3] = 5.0f, sparse[100] = 6.0f, sparse[200] = 7.5f, sparse[300] = 8.0f;
  write_floats(dir / "sparse_8x8x8_float32.raw", sparse);
  const std::string base = "optimize --ref " + dir / "ref_8x8x8_float32.raw" + " --field " +
                           dir / "sparse_8x8x8_float32.raw" + " --ref-tf " + dir / "tf.json" + " --tf-size 16 --out " +
                           dir / "o.json";
  const std::string says = "of the 16 TF entries are touched by no voxel";
  const std::string twice = " --field " + dir / "sparse_8x8x8_float32.raw" + " --shared-tf";
  for (const std::string solver : {"qp", "cgls", "irls", "eigen-cgls", "gradient-descent --iterations 20"}) {
    for (const std::string more : {std::string(), std::string(" --stream on"), twice}) {
      if (solver != "qp" && !more.empty()) continue;  // streamed and shared: the solvers of M only
      const test::CliResult r = run_cli(base + " --solver " + solver + more);
      ASSERT_EQ(r.exit_code, 0) << solver << more << "\n" << r.output;
      EXPECT_NE(r.output.find("11 " + says), std::string::npos) << solver << more << "\n" << r.output;
    }
    const test::CliResult smooth = run_cli(base + " --solver " + solver + " --smooth 1");
    ASSERT_EQ(smooth.exit_code, 0) << solver << "\n" << smooth.output;
    EXPECT_EQ(smooth.output.find("touched by no voxel"), std::string::npos) << solver << "\n" << smooth.output;
  }
  const test::CliResult ne = run_cli(base);
  ASSERT_EQ(ne.exit_code, 0) << ne.output;
  EXPECT_NE(ne.output.find("M is singular: 11 TF entries are touched by no voxel"), std::string::npos) << ne.output;
  EXPECT_EQ(ne.output.find(says), std::string::npos) << "said twice:\n" << ne.output;
}

// A field without a finite value is refused when a range is given too (a TF file's, --range), as
// it is without one: an all-infinite reference with a TF file's range wrote a constant TF with
// exit 0, and `render --range` drew an all-NaN field as an empty picture. A residual of two fields
// that never both have data is refused as optimize refuses the pair (it wrote a map of zeros).
TEST_F(CliOutputs, FieldsWithoutDataAreRefusedWhateverTheRange) {
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  write_floats(dir / "inf_8x8x8_float32.raw", std::vector<float>(512, inf));
  write_floats(dir / "nan_8x8x8_float32.raw", std::vector<float>(512, nan));
  std::vector<float> low(512, nan), high(512, nan);
  for (size_t i = 0; i < 256; ++i) low[i] = float(i) / 255.0f, high[i + 256] = float(i) / 255.0f;
  write_floats(dir / "low_8x8x8_float32.raw", low);
  write_floats(dir / "high_8x8x8_float32.raw", high);
  std::ofstream(dir / "ranged.json") << R"({"range": [0, 1], "rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
  const struct {
    std::string args, message;
  } cases[] = {
      {"optimize --ref " + dir / "inf_8x8x8_float32.raw" + " --ref-tf " + dir / "ranged.json" + " --field " +
           dir / "field_8x8x8_float32.raw" + " --out " + dir / "out.json",
       "inf_8x8x8_float32.raw: the field has no finite value"},
      {"render --volume " + dir / "nan_8x8x8_float32.raw" + " --tf " + dir / "tf.json" + " --range 0,1 --width 16 --height 16 --out " +
           dir / "out.png",
       "nan_8x8x8_float32.raw: the field has no finite value"},
      {"residual --ref " + dir / "low_8x8x8_float32.raw" + " --ref-tf " + dir / "ranged.json" + " --field " +
           dir / "high_8x8x8_float32.raw" + " --field-tf " + dir / "ranged.json" + " --out " + dir / "out.vti",
       "no voxel has data in both"},
  };
  for (const auto& c : cases) {
    const test::CliResult r = run_cli(c.args);
    EXPECT_EQ(r.exit_code, 1) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.args << "\n" << r.output;
    for (const char* name : {"out.json", "out.png", "out.vti"}) EXPECT_FALSE(fs::exists(dir.path / name)) << c.args;
  }
  // Half the voxels with data in both: a map, and not of zeros only.
  const test::CliResult r = run_cli("residual --ref " + dir / "low_8x8x8_float32.raw" + " --ref-tf " + dir / "ranged.json" +
                                    " --field " + dir / "low_8x8x8_float32.raw" + " --field-tf " + dir / "tf.json" +
                                    " --field-range 0,2 --out " + dir / "out.vti");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("mean 0, max 0 "), std::string::npos) << r.output;
}

// The residual of a field with itself is 0 everywhere, and the summary says so (not "max 1",
// the display range's fallback).
TEST_F(CliOutputs, ResidualOfAFieldWithItselfSaysZero) {
  const std::string ref = dir / "ref_8x8x8_float32.raw";
  test::CliResult r = run_cli("residual --ref " + ref + " --field " + ref + " --ref-tf " + dir / "tf.json" +
                              " --field-tf " + dir / "tf.json" + " --out " + dir / "res_8x8x8_float32.raw");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("mean 0, max 0 "), std::string::npos) << r.output;
}

// Item 6: tests that need ../shared/data skip visibly without it. The test binary runs itself
// with TFMATCH_SHARED_DATA pointing nowhere, filtered to the tests that read the data (named
// *Real* or *.Era5*).
TEST(SharedData, TestsSkipVisiblyWithoutIt) {
  test::CliResult r;
  const std::string cmd = "TFMATCH_SHARED_DATA=/nonexistent /proc/" + std::to_string(getpid()) +
                          "/exe --gtest_filter='*Real*:*.Era5*' 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) r.output.append(buf, n);
  const int status = pclose(pipe);
  // Quoted without its skip markers, which would make ctest report a failure here as a skip.
  const std::string shown = test::quoted_test_output(r.output);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << shown;
  for (const char* name :
       {"FormatsIoRealFiles.InfoDescribesVtkVtiNrrdAndRawFiles", "FormatsIoRealFiles.InfoDescribesNetcdfAndGribFiles",
        "GribRealFiles.Era5MembersAndTimesAndMultiParamSteps", "EnsembleIo.Era5GribMembersWithCoordinates",
        "EnsembleRecipe.Era5MutualInformationVersusPearson"})
    EXPECT_NE(r.output.find(std::string("[  SKIPPED ] ") + name), std::string::npos) << name << "\n" << shown;
  EXPECT_EQ(r.output.find("FAILED"), std::string::npos) << shown;
  // Every test the filter selects reads the data: none may pass without it.
  EXPECT_EQ(r.output.find("[       OK ]"), std::string::npos) << shown;
}

}  // namespace
}  // namespace tfm
