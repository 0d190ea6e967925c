// One command-line convention across subcommands, run as a user runs them: `--json FILE|-` on
// every command with JSON output, --var/--time/--member on every command that reads fields,
// solver flags of another solver and output names of another format refused as usage errors
// (exit code 2) before any work, periodic progress lines in logs, and the exit codes in --help.
#include <gtest/gtest.h>
#include <netcdf.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include "cli_runner.h"
#include "vk_test_env.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/volume.h"

namespace tfm {
namespace {

using test::run_cli;
using test::run_cli_split;
using test::TempDir;

void ok(int status) { ASSERT_EQ(status, NC_NOERR) << nc_strerror(status); }

constexpr size_t kX = 5, kY = 4, kZ = 3, kVoxels = kX * kY * kZ, kTimes = 2, kMembers = 4;

// The file's values, distinct for every variable, time and member (so a wrong selection shows).
float value_a(size_t t, size_t i) { return float(100 * t + i); }
// Not an affine map of time 0 at time 1: each maps to its own range, so equal after mapping would
// hide a wrong --time.
float value_b(size_t t, size_t i) { return 1000.0f + 50.0f * float(t) - 0.5f * float(i) + float(t * (i % 5)); }
float value_e(size_t m, size_t t, size_t i) { return float(std::sin(0.37 * double(i * (m + 1)) + 1.3 * double(t * (i % 7)))); }

// A(time, z, y, x), B(time, z, y, x) and the ensemble E(member, time, z, y, x), without
// coordinate variables (so no axis is reordered).
std::string write_netcdf(const TempDir& dir) {
  const std::string path = dir / "fields.nc";
  int nc = 0, member = 0, time = 0, z = 0, y = 0, x = 0, a = 0, b = 0, e = 0;
  EXPECT_EQ(nc_create(path.c_str(), NC_CLOBBER, &nc), NC_NOERR);
  ok(nc_def_dim(nc, "member", kMembers, &member));
  ok(nc_def_dim(nc, "time", kTimes, &time));
  ok(nc_def_dim(nc, "z", kZ, &z));
  ok(nc_def_dim(nc, "y", kY, &y));
  ok(nc_def_dim(nc, "x", kX, &x));
  const int field_dims[4] = {time, z, y, x}, ensemble_dims[5] = {member, time, z, y, x};
  ok(nc_def_var(nc, "A", NC_FLOAT, 4, field_dims, &a));
  ok(nc_def_var(nc, "B", NC_FLOAT, 4, field_dims, &b));
  ok(nc_def_var(nc, "E", NC_FLOAT, 5, ensemble_dims, &e));
  ok(nc_enddef(nc));
  std::vector<float> va, vb, ve;
  for (size_t t = 0; t < kTimes; ++t)
    for (size_t i = 0; i < kVoxels; ++i) va.push_back(value_a(t, i)), vb.push_back(value_b(t, i));
  for (size_t m = 0; m < kMembers; ++m)
    for (size_t t = 0; t < kTimes; ++t)
      for (size_t i = 0; i < kVoxels; ++i) ve.push_back(value_e(m, t, i));
  ok(nc_put_var_float(nc, a, va.data()));
  ok(nc_put_var_float(nc, b, vb.data()));
  ok(nc_put_var_float(nc, e, ve.data()));
  ok(nc_close(nc));
  return path;
}

// The finite min and max of value(i) over the grid.
template <class F>
std::pair<double, double> range_of(F value) {
  double lo = INFINITY, hi = -INFINITY;
  for (size_t i = 0; i < kVoxels; ++i) lo = std::min(lo, double(value(i))), hi = std::max(hi, double(value(i)));
  return {lo, hi};
}

// "[lo, hi]" as the commands print a range (std::cout's default format).
template <class F>
std::string printed_range(F value) {
  const auto [lo, hi] = range_of(value);
  std::ostringstream os;
  os << "[" << lo << ", " << hi << "]";
  return os.str();
}

// Equal values, NaN (no data) equal to NaN.
bool same_values(const std::vector<float>& a, const std::vector<float>& b) {
  return std::equal(a.begin(), a.end(), b.begin(), b.end(),
                    [](float x, float y) { return x == y || (std::isnan(x) && std::isnan(y)); });
}

bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

class CliConventions : public ::testing::Test {
 protected:
  void SetUp() override {
    nc = write_netcdf(dir);
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,1,0.1],[0,1,0,0.6],[1,0,0,0.9]]})";
  }
  // Expects a usage error (exit code 2) that says every needle, and that `out` was not written.
  // Refused before any work: by a short deadline, so a wrongly accepted option (a benchmark that
  // runs) fails the test instead of holding it for minutes.
  static void expect_usage_error(const std::string& args, const std::vector<std::string>& needles,
                                 const std::string& out = "") {
    const test::CliResult r = run_cli(args, test::kQuickCliTimeout);
    EXPECT_FALSE(r.timed_out) << args << "\n" << r.output;
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    for (const std::string& n : needles) EXPECT_TRUE(contains(r.output, n)) << "missing '" << n << "' in:\n" << r.output;
    if (!out.empty()) EXPECT_FALSE(std::filesystem::exists(out)) << args << " wrote " << out;
  }
  TempDir dir;
  std::string nc;
};

// The subcommands `tfmatch --help` lists.
std::vector<std::string> subcommands() {
  const std::string help = run_cli("--help").output;
  std::vector<std::string> names;
  const auto start = help.find("Subcommands:");
  std::istringstream lines(start == std::string::npos ? "" : help.substr(start));
  std::string line;
  static const std::regex entry(R"(^  ([a-z][a-z-]*)\s)");
  std::smatch m;
  while (std::getline(lines, line))
    if (std::regex_search(line, m, entry)) names.push_back(m[1]);
  return names;
}

TEST_F(CliConventions, EveryJsonOptionTakesAJsonFileOrDash) {
  const std::vector<std::string> commands = subcommands();
  ASSERT_GE(commands.size(), 15u) << run_cli("--help").output;
  std::vector<std::string> with_json;
  for (const std::string& c : commands) {
    const std::string help = run_cli(c + " --help").output;
    if (!contains(help, "--json")) continue;
    with_json.push_back(c);
    EXPECT_TRUE(contains(help, "--json FILE|-")) << c << ":\n" << help;
    // Parsed before any work: a name that is not .json is refused whatever else is missing.
    expect_usage_error(c + " --json " + dir / "out.txt", {"--json", "out.txt", "name it .json"}, dir / "out.txt");
  }
  for (const char* c : {"optimize", "solvers", "correlate", "metrics", "info", "devices", "selftest", "bench",
                        "bench-render", "bench-diffdvr", "bench-solve", "bench-correlate"})
    EXPECT_NE(std::find(with_json.begin(), with_json.end(), c), with_json.end()) << c << " has no --json";
}

// The keys docs/commands.md gives for `--json`'s `timings` object: the `NAME_ms` words of the
// paragraph that introduces it (up to the list's next item).
std::set<std::string> documented_timing_keys() {
  std::ifstream in(std::string(TFMATCH_SOURCE_DIR) + "/docs/commands.md");
  std::string text, line;
  bool in_paragraph = false;
  while (std::getline(in, line)) {
    if (line.find("carries `timings`") != std::string::npos) in_paragraph = true;
    else if (in_paragraph && line.rfind("- ", 0) == 0) break;
    if (in_paragraph) text += line + "\n";
  }
  std::set<std::string> keys;
  const std::regex name("`([a-z]+_ms)`");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), name); it != std::sregex_iterator(); ++it)
    keys.insert((*it)[1]);
  return keys;
}

TEST_F(CliConventions, JsonDashKeepsStdoutToOneJsonDocument) {
  // Commands that print text (and printf tables) otherwise: stdout must parse as JSON alone.
  const std::string raw = dir / "v_6x5x4_float32.raw";
  std::vector<float> v(120);
  for (size_t i = 0; i < v.size(); ++i) v[i] = float(i % 11);
  test::write_floats(raw, v);
  ASSERT_EQ(run_cli("render --volume " + raw + " --tf " + dir / "tf.json" + " --out " + dir / "a.png" +
                    " --width 16 --height 16").exit_code, 0);
  const std::vector<std::string> runs = {
      "info " + nc + " --json -",
      "metrics " + dir / "a.png" + " " + dir / "a.png" + " --json -",
      "optimize --ref " + raw + " --field " + raw + " --ref-tf " + dir / "tf.json" + " --out " + dir / "o.json" +
          " --tf-size 8 --json -",
      "solvers --synthetic --size 8x6x4 --solvers normal-equations --json -",
      "bench-render --size 16 --images 16 --repeat 1 --cpu-rows 2 --json -",
      "bench --sizes 9x7x5,3x2x2 --tf-sizes 4 --repeats 1 --lane-voxels 4,1000 --json -",
  };
  for (const std::string& args : runs) {
    const test::CliSplitResult r = run_cli_split(args);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.output << r.errors;
    nlohmann::json j;
    EXPECT_NO_THROW(j = nlohmann::json::parse(r.output)) << args << ": stdout is not one JSON document:\n" << r.output;
    // Every JSON object says where the run's time went, up to the moment it was written.
    if (!j.is_object()) continue;
    ASSERT_TRUE(j.contains("timings")) << args;
    EXPECT_GT(j["timings"]["total_ms"].get<double>(), j["timings"]["startup_ms"].get<double>()) << args;
    std::set<std::string> keys;
    for (const auto& [key, value] : j["timings"].items()) keys.insert(key);
    EXPECT_EQ(keys, documented_timing_keys()) << args << ": docs/commands.md's `timings` paragraph names other keys";
    // And where it comes from: tfmatch's build, and the device and driver where the run made one.
    const nlohmann::json& env = j["environment"];
    EXPECT_EQ(env["tfmatch"]["version"], TFMATCH_EXPECTED_VERSION) << args;
    EXPECT_TRUE(env["tfmatch"]["commit"].is_string()) << args;
    EXPECT_GE(env["cpu_threads"].get<int>(), 1) << args;
    const bool device = args.rfind("info ", 0) != 0 && args.rfind("metrics ", 0) != 0;
    EXPECT_EQ(env.contains("device") && env.contains("driver"), device) << args << "\n" << env.dump();
    if (device) EXPECT_NE(env["driver"].get<std::string>().find("Vulkan 1."), std::string::npos) << env.dump();
    if (args.rfind("bench --", 0) == 0) {
      for (const char* rate : {"upload_staged_bytes_per_s", "host_memcpy_bytes_per_s"})
        EXPECT_GT(j["runs"][0][rate].get<double>(), 0.0) << rate;
      EXPECT_GE(j["runs"][0]["upload_in_place_bytes_per_s"].get<double>(), 0.0);  // 0: the device cannot import
      // --lane-voxels: a row per length, each with the default's exact sums (else the run fails).
      const nlohmann::json& lanes = j["runs"][0]["lane_voxels"];
      ASSERT_EQ(lanes.size(), 2u) << j.dump(1);
      EXPECT_EQ(lanes[1]["lane_voxels"].get<int>(), 1000);
      EXPECT_GT(lanes[1]["assemble_ms"].get<double>(), 0.0);
      EXPECT_TRUE(lanes[0]["same_sums"].get<bool>());
      // A list of sizes runs each (it ran the first alone, labelled with the whole list).
      ASSERT_EQ(j["runs"].size(), 2u);
      EXPECT_EQ(j["runs"][0]["dims"], "9x7x5");
      EXPECT_EQ(j["runs"][1]["dims"], "3x2x2");
      EXPECT_EQ(j["runs"][1]["voxels"], 12);
    }
  }
  // A file instead: the text as usual, and the same JSON in the file.
  const test::CliResult text = run_cli("info " + nc + " --json " + dir / "info.json");
  ASSERT_EQ(text.exit_code, 0) << text.output;
  EXPECT_TRUE(contains(text.output, "A")) << text.output;
  std::ifstream in(dir / "info.json");
  // The same document but for the run's own timings.
  nlohmann::json in_file = nlohmann::json::parse(in), on_stdout = nlohmann::json::parse(run_cli_split("info " + nc + " --json -").output);
  EXPECT_EQ(in_file.erase("timings"), 1u);
  EXPECT_EQ(on_stdout.erase("timings"), 1u);
  EXPECT_EQ(in_file, on_stdout);
}

TEST_F(CliConventions, FieldSelectorsOnEveryCommandThatReadsFields) {
  const auto b1_of = [](size_t i) { return value_b(1, i); };
  const std::string b1 = printed_range(b1_of);
  // info: the selection as loaded, by flags or by FILE:VAR,time=N.
  for (const std::string& sel : {nc + " --var B --time 1", nc + ":B,time=1"}) {
    const test::CliSplitResult r = run_cli_split("info " + sel + " --json -");
    ASSERT_EQ(r.exit_code, 0) << sel << "\n" << r.output << r.errors;
    const nlohmann::json j = nlohmann::json::parse(r.output);
    EXPECT_EQ(j["arrays"][0]["range"][0].get<double>(), range_of(b1_of).first) << sel;
    EXPECT_EQ(j["arrays"][0]["range"][1].get<double>(), range_of(b1_of).second) << sel;
  }
  // render: the range it maps is the selected field's.
  const std::string render = "render --volume " + nc + " --tf " + dir / "tf.json" + " --out " + dir / "r.png" +
                             " --width 16 --height 16";
  test::CliResult r = run_cli(render + " --var B --time 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "range " + b1)) << b1 << "\n" << r.output;
  r = run_cli(render + " --var E --time 1 --member 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string e21 = printed_range([](size_t i) { return value_e(2, 1, i); });
  EXPECT_TRUE(contains(r.output, "range " + e21)) << e21 << "\n" << r.output;
  // residual: --time reaches --field (a field against itself is zero everywhere, another time not).
  const std::string residual = "residual --ref " + nc + ":B,time=1 --ref-tf " + dir / "tf.json" + " --field " + nc +
                               " --field-tf " + dir / "tf.json" + " --out " + dir / "res.vti --var B";
  r = run_cli(residual + " --time 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, ", max 0 ")) << r.output;
  r = run_cli(residual + " --time 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(contains(r.output, ", max 0 ")) << r.output;
  // convert-volume: the values written are the selected field's.
  r = run_cli("convert-volume " + nc + " " + dir / "a1.vti --var A --time 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Volume a1 = load_volume(dir / "a1.vti");
  ASSERT_EQ(a1.values.size(), kVoxels);
  for (size_t i = 0; i < kVoxels; ++i) ASSERT_EQ(a1.values[i], value_a(1, i)) << i;
  // Fields of one name get names of their own, each selectable (both were named A, and
  // `aa.vti:A` could only ever read the first): by their selection where it differs (a bare
  // "A_2" read as time 2 in ParaView), else numbered.
  r = run_cli("convert-volume " + nc + ":A " + nc + ":A " + dir / "aa.vti --time 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "A_time1 A_time1_2)")) << r.output;
  const Volume first = load_volume(dir / "aa.vti:A_time1"), second = load_volume(dir / "aa.vti:A_time1_2");
  ASSERT_EQ(second.values.size(), kVoxels);
  for (size_t i = 0; i < kVoxels; ++i) ASSERT_EQ(second.values[i], first.values[i]) << i;
  r = run_cli("convert-volume " + nc + ":A,time=0 " + nc + ":A,time=1 " + nc + ":B " + dir / "at.vti");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "A_time0 A_time1 B)")) << r.output;
  const Volume at1 = load_volume(dir / "at.vti:A_time1");
  for (size_t i = 0; i < kVoxels; ++i) ASSERT_EQ(at1.values[i], value_a(1, i)) << i;
  // optimize: the flags select both fields; --ref's FILE:VAR overrides only the variable.
  const test::CliSplitResult o = run_cli_split("optimize --ref " + nc + ":A --field " + nc + " --var B --time 1 --ref-tf " +
                                               dir / "tf.json" + " --out " + dir / "o.json --tf-size 8 --json -");
  ASSERT_EQ(o.exit_code, 0) << o.output << o.errors;
  const nlohmann::json summary = nlohmann::json::parse(o.output);
  EXPECT_EQ(summary["field_range"][0].get<double>(), range_of(b1_of).first);
  EXPECT_EQ(summary["field_range"][1].get<double>(), range_of(b1_of).second);
  EXPECT_EQ(summary["ref_range"][1].get<double>(), value_a(1, kVoxels - 1));
  // correlate: --time as FILE:VAR,time=N says; another time gives another field; no --member.
  auto correlate = [&](const std::string& ensemble, const std::string& out, const std::string& extra) {
    const test::CliResult c = run_cli("correlate --ensemble " + ensemble + " --point 1,1,1 --out " + dir / out + extra);
    EXPECT_EQ(c.exit_code, 0) << c.output;
    return load_volume(dir / out).values;
  };
  const std::vector<float> by_flag = correlate(nc + ":E", "c_flag.vti", " --time 1");
  const std::vector<float> by_spec = correlate(nc + ":E,time=1", "c_spec.vti", "");
  const std::vector<float> time0 = correlate(nc + ":E", "c_0.vti", "");
  EXPECT_TRUE(same_values(by_flag, by_spec));
  EXPECT_FALSE(same_values(by_flag, time0));
  expect_usage_error("correlate --ensemble " + nc + ":E --point 1,1,1 --member 1 --out " + dir / "c.vti", {"--member"},
                     dir / "c.vti");
}

TEST_F(CliConventions, SolverFlagsOfAnotherSolverAreUsageErrorsNamingTheirSolvers) {
  const std::string out = dir / "o.json";
  const std::string optimize = "optimize --ref " + nc + ":A --field " + nc + ":B --ref-tf " + dir / "tf.json" + " --out " + out;
  expect_usage_error(optimize + " --lr 0.1", {"--lr applies to solvers", "gradient-descent", "diffdvr", "not to normal-equations"},
                     out);
  // Regularization and factorization: owners from each solver's declared constraints.
  expect_usage_error(optimize + " --solver diffdvr --ridge 0.1", {"--ridge applies to solvers", "normal-equations", "not to diffdvr"},
                     out);
  expect_usage_error(optimize + " --solver cgls --factorization ldlt", {"--factorization applies to solver", "not to cgls"}, out);
  expect_usage_error("solvers --synthetic --size 8x6x4 --solvers cgls,qp --lr 0.1", {"--lr applies to", "not to qp, cgls"});
  // What applies still runs.
  EXPECT_EQ(run_cli(optimize + " --factorization ldlt --tf-size 8").exit_code, 0);
}

// Picture flags without --report are usage errors naming them, except where the fit itself
// renders (diffdvr, --weights visibility): they were accepted and dropped without a word.
TEST_F(CliConventions, OptimizePictureFlagsWithoutAReportAreUsageErrors) {
  const std::string out = dir / "o.json";
  const std::string optimize = "optimize --ref " + nc + ":A --field " + nc + ":B --ref-tf " + dir / "tf.json" + " --out " + out;
  expect_usage_error(optimize + " --width 100 --azimuth 10",
                     {"--azimuth, --width: shape the report's pictures", "diffdvr or --weights visibility", "add --report DIR"},
                     out);
  expect_usage_error(optimize + " --background black", {"--background: shapes the report's pictures"}, out);
  expect_usage_error(optimize + " --histogram linear", {"--histogram: shapes the report's pictures: add --report DIR"}, out);
  // A series the same way.
  expect_usage_error(optimize + " --field " + nc + ":A --fov 20", {"--fov: shapes the report's pictures"}, out);
  // Where the fit renders, the camera and image flags shape it; the histogram still needs a report.
  const std::string fit = optimize + " --weights visibility --weight-views 1 --tf-size 4 --width 16 --height 16";
  EXPECT_EQ(run_cli(fit).exit_code, 0);
  expect_usage_error(fit + " --histogram linear", {"--histogram: shapes the report's pictures"});
  EXPECT_EQ(run_cli(optimize + " --solver diffdvr --iterations 1 --views-per-iteration 1 --view-pool 1 --tf-size 4 --width 16 --height 16")
                .exit_code,
            0);
  EXPECT_EQ(run_cli(optimize + " --width 32 --height 32 --report " + dir / "rep").exit_code, 0);
}

// Grid sizes are three positive integers and nothing else, every one of a list checked before
// any work (bench read "8x8x8junk" as 8x8x8, and found a bad size after running the others).
TEST_F(CliConventions, GridSizesAreUsageErrorsBeforeAnyWork) {
  const std::string json = dir / "bench.json";
  for (const std::string bad : {"8x8x8junk", "-5x8x8", "8x8", "0x4x4", "8x8x8,bad", "1234567890123x1x1"})
    expect_usage_error("bench --sizes " + bad + " --tf-sizes 4 --repeats 1 --json " + json,
                       {"--sizes: expected a grid size XxYxZ of positive integers"}, json);
  expect_usage_error("solvers --synthetic --size 8x6x4x2 --solvers normal-equations",
                     {"--size: expected a grid size XxYxZ of positive integers, got '8x6x4x2'"});
}

// Flags that say how to read or map input files are refused where a built-in pair replaces the
// files (bench-solve without --ref, solvers --synthetic): they were accepted and ignored.
TEST(CliExitCodes, InputFlagsWithoutInputsAreUsageErrors) {
  for (const std::string flag : {"--ref-range 0,1", "--field-range 0,1", "--allow-out-of-range", "--dims 4,4,4",
                                 "--type uint8", "--big-endian", "--var t", "--time 1", "--member 2"}) {
    const std::string name = flag.substr(0, flag.find(' '));
    for (const std::string command : {"bench-solve --tf-sizes 4", "solvers --synthetic --size 4x4x4 --solvers normal-equations"}) {
      const test::CliResult r = run_cli(command + " " + flag, test::kQuickCliTimeout);
      EXPECT_EQ(r.exit_code, 2) << command << " " << flag << "\n" << r.output;
      EXPECT_TRUE(contains(r.output, name + ": describes the input files")) << r.output;
    }
  }
}

TEST_F(CliConventions, OutputNamesMustNameTheFormatWritten) {
  const std::string tf = dir / "tf.json";
  const std::string render = "render --volume " + nc + ":A --tf " + tf + " --width 16 --height 16 --out ";
  expect_usage_error(render + dir / "x.jpg", {"--out", "x.jpg", "PNG image", "name it .png"}, dir / "x.jpg");
  const std::string residual = "residual --ref " + nc + ":A --ref-tf " + tf + " --field " + nc + ":B --field-tf " + tf;
  expect_usage_error(residual + " --out " + dir / "r.png", {"--out", "name it .vti or .raw"}, dir / "r.png");
  expect_usage_error(residual + " --out " + dir / "r.vti --image " + dir / "r.jpg", {"--image", "name it .png"}, dir / "r.vti");
  expect_usage_error("optimize --ref " + nc + ":A --field " + nc + ":B --ref-tf " + tf + " --out " + dir / "t.txt",
                     {"--out", "transfer function", ".xml"}, dir / "t.txt");
  expect_usage_error("convert-tf " + tf + " " + dir / "t.png", {"name it .json or .xml"}, dir / "t.png");
  expect_usage_error("convert-volume " + nc + ":A " + dir / "v.raw", {"v.raw", "name it .vti"}, dir / "v.raw");
  expect_usage_error("correlate --ensemble " + nc + ":E --point 1,1,1 --out " + dir / "c.png", {"name it .vti or .raw"},
                     dir / "c.png");
  // Extensions compare without case, for the check and for the format written; a ParaView preset
  // is a .json.
  EXPECT_EQ(run_cli(render + dir / "X.PNG").exit_code, 0);
  ASSERT_EQ(run_cli(residual + " --out " + dir / "R.VTI").exit_code, 0);
  std::ifstream vti(dir / "R.VTI");
  const std::string head((std::istreambuf_iterator<char>(vti)), std::istreambuf_iterator<char>());
  EXPECT_NE(head.find("<VTKFile"), std::string::npos) << "R.VTI was not written as VTK ImageData";
  EXPECT_EQ(run_cli("convert-tf " + tf + " " + dir / "t.paraview.json").exit_code, 0);
  // The two-part extension too: T.PARAVIEW.JSON is a ParaView preset (a list of one object with
  // "RGBPoints"), not a tfmatch table (it was).
  ASSERT_EQ(run_cli("convert-tf " + tf + " " + dir / "T.PARAVIEW.JSON").exit_code, 0);
  const nlohmann::json preset = nlohmann::json::parse(std::ifstream(dir / "T.PARAVIEW.JSON"));
  ASSERT_TRUE(preset.is_array()) << preset.dump();
  EXPECT_TRUE(preset[0].contains("RGBPoints")) << preset.dump();
  EXPECT_EQ(preset[0]["Name"], "T") << preset.dump();
}

TEST_F(CliConventions, ProgressInALogIsPeriodicPlainLines) {
  const std::string render = "render --volume " + nc + ":A --tf " + dir / "tf.json" + " --out " + dir / "p.png" +
                             " --width 64 --height 64";
  // run_cli's stderr is a pipe; a tiny interval makes every band of the render a line. Set in
  // the children only: this process's own progress lines keep their interval.
  const test::CliEnvironment tiny_interval = {{"TFMATCH_PROGRESS_INTERVAL", "0.000001"}};
  const test::CliResult r = run_cli(render, test::kCliTimeout, tiny_interval);
  const test::CliResult quiet = run_cli("-q " + render, test::kCliTimeout, tiny_interval);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  static const std::regex line(R"(rendering: \d+% \(\d+/64\), [0-9.]+s elapsed, (~[0-9.]+s|\?) left\n)");
  EXPECT_TRUE(std::regex_search(r.output, line)) << r.output;
  EXPECT_FALSE(contains(r.output, "\033[K")) << "terminal control codes in a log";
  EXPECT_EQ(quiet.exit_code, 0);
  EXPECT_FALSE(contains(quiet.output, "rendering:")) << quiet.output;
  // The default interval (10 s): a run of a second prints no progress at all.
  EXPECT_FALSE(contains(run_cli(render).output, "rendering:"));
}

// -q drops summaries and notes but keeps warnings, on stderr: a range that leaves most values
// outside it is said by optimize alone and by a series of fields, as by render.
TEST_F(CliConventions, QuietKeepsWarnings) {
  const std::string tf = dir / "tf.json";
  const std::vector<std::string> runs = {
      "optimize --ref " + nc + ":A --ref-tf " + tf + " --field " + nc + ":B --out " + dir / "one.json" +
          " --ref-range 0,10",
      "optimize --ref " + nc + ":A --ref-tf " + tf + " --field " + nc + ":B,time=0..1 --out " + dir / "many.json" +
          " --ref-range 0,10",
      "render --volume " + nc + ":A --tf " + tf + " --out " + dir / "a.png" + " --width 32 --height 32 --range 0,10"};
  for (const std::string& args : runs) {
    const test::CliSplitResult r = test::run_cli_split("-q " + args);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.output << r.errors;
    EXPECT_EQ(r.output, "") << args;
    EXPECT_TRUE(contains(r.errors, "tfmatch: warning: ")) << args << "\n" << r.errors;
    EXPECT_TRUE(contains(r.errors, "of its finite values lie outside the")) << args << "\n" << r.errors;
    EXPECT_FALSE(contains(r.errors, "note:")) << args << "\n" << r.errors;
  }
}

// TFMATCH_VALIDATION=1 where the layer cannot be found (VK_LAYER_PATH names an empty folder)
// runs, as the tests need, but says that the run is not validated; --validation refuses.
TEST_F(CliConventions, ValidationVariableWithoutTheLayerIsSaid) {
  const std::string tf = dir / "tf.json";
  const std::string args = "render --volume " + nc + ":A --tf " + tf + " --out " + dir / "v.png" + " --width 16 --height 16";
  const test::CliEnvironment no_layer{{"VK_LAYER_PATH", dir / "no-layers"}, {"TFMATCH_VALIDATION", "1"}};
  std::filesystem::create_directories(dir / "no-layers");
  const test::CliResult r = run_cli(args, test::kCliTimeout, no_layer);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "tfmatch: warning: TFMATCH_VALIDATION=1, but the Khronos validation layer is not "
                                 "installed: this run is not validated"))
      << r.output;
  const test::CliResult strict = run_cli("--validation " + args, test::kCliTimeout, no_layer);
  EXPECT_EQ(strict.exit_code, 1) << strict.output;
  EXPECT_TRUE(contains(strict.output, "requested but not installed")) << strict.output;
  // Where the layer is found, no such warning (the test process itself runs validated).
  if (test::context().validation_enabled())
    EXPECT_FALSE(contains(run_cli(args).output, "not validated"));
}

// A benchmark that sets image sizes, steps or TF sizes by its own flags refuses the shared ones it
// would ignore (usage errors, before any work).
TEST(CliExitCodes, BenchmarksRefuseRenderFlagsTheyWouldIgnore) {
  for (const std::string args :
       {"bench-render --width 64", "bench-render --height 64", "bench-diffdvr --step 0.5", "bench-solve --tf-size 8"}) {
    const test::CliResult r = run_cli(args, test::kQuickCliTimeout);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, args.substr(args.find(' ') + 1, args.rfind(' ') - args.find(' ') - 1))) << r.output;
  }
}

// Each exit code for the reason its message gives: the required options are all there when the
// unknown one is what must be refused (else "--volume is required" would pass for it).
TEST(CliExitCodes, DocumentedInHelpAndReturned) {
  const test::CliResult help = run_cli("--help", test::kQuickCliTimeout);
  EXPECT_EQ(help.exit_code, 0);
  for (const char* s : {"Exit codes:", "usage", "130", "143"}) EXPECT_TRUE(contains(help.output, s)) << s << "\n" << help.output;
  TempDir dir;
  auto expect_exit = [](const std::string& args, int code, const std::string& message) {
    const test::CliResult r = run_cli(args, test::kQuickCliTimeout);
    EXPECT_FALSE(r.timed_out) << args << "\n" << r.output;
    EXPECT_EQ(r.exit_code, code) << args << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, message)) << args << ": no '" << message << "' in\n" << r.output;
  };
  expect_exit("render --volume " + dir / "v.raw" + " --tf " + dir / "t.json" + " --out " + dir / "o.png" +
                  " --no-such-flag",
              2, "The following argument was not expected: --no-such-flag");
  expect_exit("info", 2, "files is required");  // a missing required argument is a usage error
  expect_exit("info " + dir / "missing.nc", 1, dir / "missing.nc" + ": no such file");
}

}  // namespace
}  // namespace tfm
