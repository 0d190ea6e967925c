// tools/gpu_targets.py, the table of issues 28 and 29's GPU goals that tools/gpu-check.sh writes
// after every step: fed the JSON of real small runs of the benchmarks on this device (with
// --any-size, since the goals are at sizes lavapipe takes minutes for), a summary.txt in
// gpu-check's format and a PyTorch peer's file made from tfmatch's own numbers, so each verdict is
// checked against the figures it must be drawn from.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/kernels/reduction.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string python() { return fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3"; }

test::CliResult targets(const fs::path& dir, const std::string& options) {
  return test::run_shell(python() + " " + TFMATCH_SOURCE_DIR + "/tools/gpu_targets.py " + dir.string() + " " + options);
}

json read_json(const fs::path& p) { return json::parse(std::ifstream(p)); }

void write_json(const fs::path& p, const json& j) { std::ofstream(p) << j.dump(1); }

// The table's rows by goal.
std::map<std::string, json> rows_by_goal(const json& result) {
  std::map<std::string, json> rows;
  for (const json& row : result["rows"]) rows[row["goal"].get<std::string>()] = row;
  return rows;
}

std::string verdict(bool met) { return met ? "met" : "missed"; }

class GpuTargets : public ::testing::Test {
 protected:
  void SetUp() override {
    if (test::run_shell(python() + " -c 'import argparse, json'").exit_code != 0) GTEST_SKIP() << "no python3";
  }
  test::TempDir dir;
};

TEST_F(GpuTargets, JudgesTheBenchmarksRunsAgainstEachGoal) {
  const auto run = [&](const std::string& args) {
    const test::CliResult r = test::run_cli(args);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.output;
  };
  run("-q bench --sizes 24x20x10 --tf-sizes 16,64,256,1024 --repeats 1 --lane-voxels 16,64 --json " + (dir / "bench.json"));
  run("-q bench-correlate --voxels 64 --members 10,100,1000 --measures pearson,spearman,kendall --max-values 100000 --json " +
      (dir / "bench-correlate.json"));
  run("-q bench-diffdvr --size 16 --image-size 32 --views 2 --repeat 1 --steps 0.5,0.25 --json " + (dir / "bench-diffdvr.json"));
  run("-q bench-stream --voxels 40000 --stream off --dir " + dir.path.string() + " --json " + (dir / "bench-stream-off.json"));
  run("-q solvers --synthetic --size 24x20x10 --solvers normal-equations --json " + (dir / "solvers-combustion.json"));
  fs::create_directories(dir.path / "e2e-work");
  const test::CliResult e2e = test::run_shell(python() + " " + TFMATCH_SOURCE_DIR + "/tools/e2e_timing.py " +
                                              TFMATCH_CLI_PATH + " --pair 24x20x9 --ensemble 4x13x11x3 --runs 1 --dir " +
                                              (dir / "e2e-work") + " --json " + (dir / "e2e.json"));
  ASSERT_EQ(e2e.exit_code, 0) << e2e.output;
  // gpu-check's summary lines, and the CUDA tests' log as that step writes it where ctest is missing.
  const test::CliResult cuda = test::run_shell(std::string(TFMATCH_BUILD_DIR) +
                                               "/tests/tfmatch_tests --gtest_filter='Cuda*' --gtest_brief=1");
  std::ofstream(dir.path / "cuda-tests.log") << cuda.output;
  std::ofstream(dir.path / "summary.txt") << "selftest               rc=0      2.1 s\n"
                                             "ctest                  rc=8     50.3 s\n"
                                             "cuda-tests             rc=" << cuda.exit_code << "      3.0 s\n"
                                             "view-512               skipped: under 5 s left before the --deadline of 540 s\n";
  // A PyTorch peer slower than tfmatch at Pearson, faster at Spearman and 10 % above its read bound.
  const json bench = read_json(dir.path / "bench.json"), correlate = read_json(dir.path / "bench-correlate.json");
  const json& pair = bench["runs"][0];
  json peer = {{"torch", "test peer"}, {"read_bytes_per_s", pair["read_bound_voxels_per_s"].get<double>() * 8 / 0.9},
               {"correlation", json::array()}};
  for (const json& row : correlate["results"]) {
    const std::string measure = row["measure"];
    if (measure == "kendall") continue;
    const double ours = row["resident_voxels_per_s"];
    peer["correlation"].push_back({{"measure", measure}, {"members", row["members"]}, {"voxels", row["voxels"]},
                                   {"voxels_per_s", measure == "pearson" ? ours / 2 : ours * 2}});
  }
  write_json(dir.path / "torch.json", peer);

  const test::CliResult table = targets(dir.path, "--any-size --json " + (dir / "targets.json"));
  ASSERT_EQ(table.exit_code, 0) << table.output;
  auto rows = rows_by_goal(read_json(dir.path / "targets.json"));
  EXPECT_EQ(rows["read bound"]["verdict"], "missed") << rows["read bound"];  // 0.9 of PyTorch's
  bool all_half = true;
  for (const json& n : pair["tf_sizes"]) all_half = all_half && n["gpu_over_read_bound"].get<double>() >= 0.5;
  EXPECT_EQ(rows["assembly / read bound"]["verdict"], verdict(all_half));
  EXPECT_EQ(rows["upload"]["verdict"], verdict(pair["upload_in_place_bytes_per_s"].get<double>() >= 40e9));
  EXPECT_EQ(rows["lane length sweep"]["verdict"], "no goal");
  EXPECT_EQ(rows["pearson"]["verdict"], "met") << rows["pearson"];
  EXPECT_EQ(rows["spearman"]["verdict"], "missed") << rows["spearman"];
  bool kendall_20x = true;
  for (const json& row : correlate["results"])
    if (row["measure"] == "kendall")
      kendall_20x = kendall_20x && row["resident_voxels_per_s"].get<double>() >= 20 * row["cpu_voxels_per_s"].get<double>();
  EXPECT_EQ(rows["kendall"]["verdict"], verdict(kendall_20x));
  EXPECT_EQ(rows["mi-binned"]["verdict"], "not measured");  // not run
  bool pearson_10 = false;
  for (const json& row : correlate["results"])
    if (row["measure"] == "pearson" && row["members"] == 10) {
      pearson_10 = true;
      EXPECT_EQ(rows["pearson / read bound"]["verdict"], verdict(row["resident_over_read_bound"].get<double>() >= 0.5));
    }
  EXPECT_TRUE(pearson_10) << correlate.dump(1);
  const json timing = read_json(dir.path / "e2e.json");
  EXPECT_EQ(rows["optimize end to end"]["verdict"], verdict(timing["optimize"]["median_ms"].get<double>() <= 350));
  EXPECT_EQ(rows["correlate end to end"]["verdict"], verdict(timing["correlate"]["median_ms"].get<double>() <= 300));
  // optimize's own assembly kernel, from the phases e2e_timing.py keeps, beside bench's.
  EXPECT_NE(rows["assembly in bench = in optimize"]["verdict"], "not measured") << rows["assembly in bench = in optimize"];
  const json stream = read_json(dir.path / "bench-stream-off.json");
  EXPECT_EQ(rows["optimize from disk"]["verdict"], verdict(stream["runs"][0]["optimize_over_read"].get<double>() <= 1.5));
  EXPECT_EQ(rows["cuda-normal-equations"]["verdict"], "not measured");  // no row of it
  bool diffdvr = true;
  const json diffdvr_json = read_json(dir.path / "bench-diffdvr.json");
  const json diffdvr_rows = diffdvr_json["iterations"];
  ASSERT_FALSE(diffdvr_rows.empty());
  // Which summing path the backward pass took, as the table's header names it.
  const std::string backward = diffdvr_json.value("backward_reduction", std::string());
  EXPECT_TRUE(backward == reduction_mode_name(ReductionMode::Private) ||
              backward == reduction_mode_name(ReductionMode::RunsShared) ||
              backward == reduction_mode_name(ReductionMode::RunsGlobal))
      << diffdvr_json.dump();
  for (const json& row : diffdvr_rows)
    diffdvr = diffdvr && row["iteration_over_forward_only"].get<double>() <= 2.5;
  EXPECT_EQ(rows["DiffDVR iteration / forward"]["verdict"], verdict(diffdvr));
  EXPECT_EQ(rows["view 512²"]["verdict"], "not measured");
  EXPECT_NE(rows["view 512²"]["note"].get<std::string>().find("skipped (deadline)"), std::string::npos);
  EXPECT_NE(rows["view 1024²"]["note"].get<std::string>().find("did not run"), std::string::npos);
  EXPECT_EQ(rows["self-test"]["verdict"], "met");
  EXPECT_EQ(rows["test suite"]["verdict"], "missed");
  // Without a CUDA device the CUDA tests skip: passing, but nothing was measured on a GPU.
  const bool cuda_skipped = cuda.output.find("[  SKIPPED ]") != std::string::npos;
  EXPECT_EQ(rows["CUDA tests"]["verdict"], cuda.exit_code ? "missed" : cuda_skipped ? "not measured" : "met")
      << rows["CUDA tests"] << "\n" << test::quoted_test_output(cuda.output);
  // The Markdown table has a line per row.
  size_t lines = 0;
  for (size_t at = table.output.find("\n| "); at != std::string::npos; at = table.output.find("\n| ", at + 1)) ++lines;
  EXPECT_EQ(lines, rows.size() + 2) << table.output;  // and the header and its rule

  // At the goals' own sizes these small runs measure nothing, and the table says which size it wanted.
  ASSERT_EQ(targets(dir.path, "--json " + (dir / "targets.json")).exit_code, 0);
  rows = rows_by_goal(read_json(dir.path / "targets.json"));
  for (const char* goal : {"read bound", "upload", "pearson / read bound", "optimize end to end", "optimize from disk", "cuda-cgls"})
    EXPECT_EQ(rows[goal]["verdict"], "not measured") << goal;
  EXPECT_NE(rows["read bound"]["note"].get<std::string>().find("480x720x120"), std::string::npos);
  EXPECT_NE(rows["pearson / read bound"]["note"].get<std::string>().find("1760000"), std::string::npos);
}

TEST_F(GpuTargets, FilesThatAreNotTheirStepsJsonAreNamed) {
  EXPECT_EQ(targets(dir.path / "no-such-folder", "").exit_code, 2);
  // An empty folder: every goal not measured, none judged.
  test::CliResult r = targets(dir.path, "--json " + (dir / "targets.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto empty = rows_by_goal(read_json(dir.path / "targets.json"));
  EXPECT_GE(empty.size(), 20u);
  for (const auto& [goal, row] : empty) EXPECT_EQ(row["verdict"], "not measured") << goal;
  fs::remove(dir.path / "targets.json");
  for (const std::string& bad : {std::string("{\"runs\": [{\"dims\": \"480x720x1"), std::string("{\"runs\": [{\"dims\": \"480x720x120\"}]}"),
                                 std::string("[1, 2]")}) {
    std::ofstream(dir.path / "bench.json") << bad;
    r = targets(dir.path, "--json " + (dir / "targets.json"));
    EXPECT_EQ(r.exit_code, 1) << bad << "\n" << r.output;
    EXPECT_NE(r.output.find((dir / "bench.json")), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("Traceback"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir.path / "targets.json")) << bad;
  }
}

}  // namespace
}  // namespace tfm
