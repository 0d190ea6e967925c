// `tfmatch optimize` on bad input: a clear message naming the file and the problem, a non-zero
// exit, and no output file — run as a separate process, as a user runs it.
#include <fstream>
#include <regex>

#include <gtest/gtest.h>

#include "cli_runner.h"
#include "tfmatch/io/tf_json.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm {
namespace {

using test::run_cli;
using test::TempDir;
using test::write_floats;


void write_text(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

std::vector<float> ramp(size_t n, float scale = 1.0f) {
  std::vector<float> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = scale * float(i % 17) / 16.0f;
  return v;
}

class CliErrors : public ::testing::Test {
 protected:
  void SetUp() override {
    write_floats(dir / "ref_4x4x4_float32.raw", ramp(64));
    write_floats(dir / "field_4x4x4_float32.raw", ramp(64, 3.0f));
    write_text(dir / "tf.json", R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})");
  }
  // Runs optimize with the given overrides; expects failure mentioning every `needles` entry
  // and that --out was not created.
  void expect_failure(const std::string& args, std::vector<std::string> needles) {
    std::string out = dir / "out.json";
    auto r = run_cli("optimize --out " + out + " " + args);
    EXPECT_NE(r.exit_code, 0) << r.output;
    for (const auto& n : needles) EXPECT_NE(r.output.find(n), std::string::npos) << "missing '" << n << "' in:\n" << r.output;
    EXPECT_FALSE(std::filesystem::exists(out)) << "a failed run left " << out;
    EXPECT_EQ(r.output.find("Segmentation"), std::string::npos);
  }
  std::string ok_inputs(const std::string& ref = "", const std::string& field = "", const std::string& tf = "") {
    return "--ref " + (ref.empty() ? dir / "ref_4x4x4_float32.raw" : ref) + " --field " +
           (field.empty() ? dir / "field_4x4x4_float32.raw" : field) + " --ref-tf " + (tf.empty() ? dir / "tf.json" : tf);
  }
  TempDir dir;
};

TEST_F(CliErrors, MissingFile) {
  expect_failure(ok_inputs(dir / "nope_4x4x4_float32.raw"), {"nope_4x4x4_float32.raw", "no such file"});
}

// A missing or unreadable input is an error naming it (exit 1) in every command: metrics said
// "B: File does not exist" as a usage error, and read a directory as "Read Error". An unknown
// element type is a bad option value: a usage error (exit 2), as --dims 0 is.
TEST_F(CliErrors, InputsThatAreNoFilesAndUnknownTypes) {
  auto r = run_cli("metrics " + dir / "nope.png" + " " + dir / "nope2.png");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("tfmatch: error: " + dir / "nope.png" + ": no such file"), std::string::npos) << r.output;
  std::filesystem::create_directory(dir / "pics");
  r = run_cli("metrics " + dir / "pics" + " " + dir / "pics");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("pics: is a directory, not a PNG image"), std::string::npos) << r.output;
  r = run_cli("info " + dir / "ref_4x4x4_float32.raw" + " --type complex64");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--type: unknown element type 'complex64'"), std::string::npos) << r.output;
}

TEST_F(CliErrors, WrongSizeRaw) {
  write_floats(dir / "short_4x4x4_float32.raw", ramp(60));
  expect_failure(ok_inputs(dir / "short_4x4x4_float32.raw"), {"short_4x4x4_float32.raw", "240 bytes", "needs 256"});
}

TEST_F(CliErrors, RawWithoutDimensions) {
  write_floats(dir / "plain.raw", ramp(64));
  expect_failure(ok_inputs(dir / "plain.raw"), {"plain.raw", "--dims"});
}

// A file name and --dims or --type that disagree: reading either way could give a wrong field
// that looks plausible (4x4x4 floats read as 2x4x8 is a reshuffled field); both used to be
// silently overridden by the option.
TEST_F(CliErrors, RawNameAndOptionsThatDisagree) {
  expect_failure(ok_inputs() + " --dims 2,4,8",
                 {"ref_4x4x4_float32.raw", "the file name says 4x4x4", "--dims says 2x4x8"});
  expect_failure(ok_inputs() + " --type int32",
                 {"ref_4x4x4_float32.raw", "the file name says float32", "--type says int32"});
  // Options that agree with the name, or that a plain file needs, still read.
  auto agree = run_cli("optimize --out " + dir / "agree.json" + " " + ok_inputs() + " --dims 4,4,4 --type float32");
  EXPECT_EQ(agree.exit_code, 0) << agree.output;
  write_floats(dir / "plain.raw", ramp(64, 3.0f));
  auto plain = run_cli("optimize --out " + dir / "plain.json" + " " + ok_inputs("", dir / "plain.raw") +
                       " --dims 4,4,4 --type float32");
  EXPECT_EQ(plain.exit_code, 0) << plain.output;
}

// --dims, --type and --big-endian describe headerless raw files; given where no input is one they
// used to be ignored without a word (a NetCDF or NRRD file says its own grid and type).
TEST_F(CliErrors, RawFlagsWhereNoInputIsRaw) {
  std::string nrrd = "NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\nencoding: ascii\n\n";
  for (float v : ramp(64, 2.0f)) nrrd += std::to_string(v) + "\n";
  write_text(dir / "a.nrrd", nrrd);
  write_text(dir / "b.nrrd", nrrd);
  const std::string pair = "--ref " + dir / "a.nrrd" + " --field " + dir / "b.nrrd" + " --ref-tf " + dir / "tf.json";
  expect_failure(pair + " --dims 4,4,4", {"--dims", "describes raw files", "a.nrrd (NRRD)", "b.nrrd (NRRD)"});
  expect_failure(pair + " --type float32", {"--type", "describes raw files"});
  expect_failure(pair + " --big-endian", {"--big-endian", "describes raw and .dat files"});
  for (const std::string cmd : {"info " + dir / "a.nrrd", "render --tf viridis --out " + dir / "a.png" + " --volume " + dir / "a.nrrd"}) {
    auto r = run_cli(cmd + " --type uint8");
    EXPECT_EQ(r.exit_code, 2) << cmd << "\n" << r.output;
    EXPECT_NE(r.output.find("--type: describes raw files, and no input is one: a.nrrd (NRRD)"), std::string::npos) << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "a.png"));
  // With a raw input beside the NRRD one, the flags describe it.
  auto mixed = run_cli("optimize --out " + dir / "mixed.json" + " --ref " + dir / "a.nrrd" + " --field " +
                       dir / "field_4x4x4_float32.raw" + " --ref-tf " + dir / "tf.json" + " --type float32");
  EXPECT_EQ(mixed.exit_code, 0) << mixed.output;
}

TEST_F(CliErrors, ConstantField) {
  write_floats(dir / "const_4x4x4_float32.raw", std::vector<float>(64, 2.5f));
  expect_failure(ok_inputs("", dir / "const_4x4x4_float32.raw"), {"const_4x4x4_float32.raw", "constant"});
}

TEST_F(CliErrors, GridsOfDifferentSize) {
  write_floats(dir / "other_4x4x5_float32.raw", ramp(80));
  expect_failure(ok_inputs("", dir / "other_4x4x5_float32.raw"), {"different grids", "4x4x5", "4x4x4"});
}

TEST_F(CliErrors, MalformedTransferFunctions) {
  write_text(dir / "bad_json.json", "{\"rgba\": [[0,0,0,0], [1,1,1");
  expect_failure(ok_inputs("", "", dir / "bad_json.json"), {"bad_json.json", "not valid JSON"});
  write_text(dir / "three.json", R"({"rgba": [[0,0,0,0],[1,1,1]]})");
  expect_failure(ok_inputs("", "", dir / "three.json"), {"three.json", "row 1", "not 4 numbers"});
  write_text(dir / "range.json", R"({"rgba": [[0,0,0,0],[1,2,1,1]]})");
  expect_failure(ok_inputs("", "", dir / "range.json"), {"range.json", "outside [0,1]"});
  write_text(dir / "one.json", R"({"rgba": [[0,0,0,0]]})");
  expect_failure(ok_inputs("", "", dir / "one.json"), {"one.json", "at least 2 entries"});
  write_text(dir / "norgba.json", R"({"colors": []})");
  expect_failure(ok_inputs("", "", dir / "norgba.json"), {"norgba.json", "rgba"});
}

TEST_F(CliErrors, TooSmallTfSize) {
  expect_failure(ok_inputs() + " --tf-size 1", {"--tf-size"});
}

TEST_F(CliErrors, BadRange) {
  expect_failure(ok_inputs() + " --field-range 5,1", {"range", "lo < hi"});
  expect_failure(ok_inputs() + " --field-range abc", {"--field-range", "lo,hi"});
}

TEST_F(CliErrors, AllNanField) {
  write_floats(dir / "nan_4x4x4_float32.raw", std::vector<float>(64, NAN));
  expect_failure(ok_inputs("", dir / "nan_4x4x4_float32.raw"), {"nan_4x4x4_float32.raw", "no finite value"});
}

// `residual` renders only with --image: picture settings without it are a usage error naming
// them (they were accepted and dropped), and with it they shape the picture.
TEST_F(CliErrors, ResidualPictureSettingsNeedAnImage) {
  const std::string args = "residual --ref " + dir / "ref_4x4x4_float32.raw" + " --ref-tf " + dir / "tf.json" +
                           " --field " + dir / "field_4x4x4_float32.raw" + " --field-tf " + dir / "tf.json" + " --out " +
                           dir / "r.raw";
  auto r = run_cli(args + " --width 64 --step 2");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--width, --step: shape the residual's picture: add --image"), std::string::npos) << r.output;
  r = run_cli(args + " --display-range 0,1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--display-range: shapes the residual's picture"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "r.raw"));
  r = run_cli(args + " --image " + dir / "r.png" + " --width 64 --height 48 --display-range 0,1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir / "r.png"));
}

// The working case: a 3-entry reference TF, an optimized TF of another size, JSON summary.
TEST_F(CliErrors, DifferentTfSizesWork) {
  std::string out = dir / "out.json", summary = dir / "summary.json";
  auto r = run_cli("optimize --out " + out + " --json " + summary + " --tf-size 9 " + ok_inputs());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  TransferFunction tf = read_tf_json(out);
  EXPECT_EQ(tf.size(), 9u);
  ASSERT_TRUE(tf.range.has_value());
  EXPECT_DOUBLE_EQ(tf.range->hi, 3.0);
  EXPECT_TRUE(std::filesystem::exists(summary));
  EXPECT_NE(r.output.find("voxel RMSE"), std::string::npos);
}

// Help prints and exits without doing the command's work; a deadline makes a --help that were
// taken for a run (a benchmark, a demo) fail rather than run for minutes.
TEST(CliHelp, EverySubcommandHasHelp) {
  for (const char* sub : {"optimize", "demo", "devices", "bench"}) {
    auto r = run_cli(std::string(sub) + " --help", test::kQuickCliTimeout);
    EXPECT_FALSE(r.timed_out) << sub << ": " << r.output;
    EXPECT_EQ(r.exit_code, 0) << sub;
    EXPECT_TRUE(std::regex_search(r.output, std::regex("\nUsage: \\S*tfmatch " + std::string(sub) + " \\[OPTIONS\\]")))
        << sub << ": " << r.output;
  }
  auto r = run_cli("no-such-command", test::kQuickCliTimeout);
  EXPECT_FALSE(r.timed_out) << r.output;
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("A subcommand is required"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace tfm
