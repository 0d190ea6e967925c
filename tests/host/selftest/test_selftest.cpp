// The conformance self-test (host/selftest/selftest.h) and the commands around it: the quick run
// passes on the test device and covers every shaders/*.comp kernel, every check can fail (a
// perturbed device value fails every case), and `tfmatch selftest`, `tfmatch --version` and
// `tfmatch devices --json` work as a tester runs them.
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "cli_runner.h"
#include "tfmatch/io/json.h"
#include "tfmatch/selftest/selftest.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

// The stems of shaders/*.comp, listed at configure time (tests/CMakeLists.txt).
std::vector<std::string> shader_names() {
  std::vector<std::string> out;
  std::stringstream ss(TFMATCH_SHADER_STEMS);
  for (std::string s; std::getline(ss, s, ',');)
    if (!s.empty()) out.push_back(s);
  return out;
}

// The JSON document in a command's output (stdout alone when run with -q).
nlohmann::json parse_json(const std::string& output) {
  const size_t begin = output.find('{'), end = output.rfind('}');
  if (begin == std::string::npos || end == std::string::npos) return nlohmann::json();
  return nlohmann::json::parse(output.substr(begin, end - begin + 1), nullptr, false);
}

TEST(Selftest, CoversEveryComputeShader) {
  const std::vector<std::string> shaders = shader_names();
  ASSERT_GE(shaders.size(), 10u) << "the shader list did not reach the test: " << TFMATCH_SHADER_STEMS;
  const std::vector<std::string> covered = selftest_kernels();
  for (const std::string& s : shaders)
    EXPECT_NE(std::find(covered.begin(), covered.end(), s), covered.end()) << "no self-test case runs " << s << ".comp";
}

// `selftest --quick` runs at least one case of every kernel (the case table, without a device).
TEST(Selftest, QuickCasesCoverEveryComputeShader) {
  std::set<std::string> quick;
  for (const SelftestCaseEntry& e : selftest_cases())
    if (e.quick) quick.insert(e.kernel);
  ASSERT_GE(shader_names().size(), 10u);
  for (const std::string& s : shader_names()) EXPECT_TRUE(quick.count(s)) << "no quick self-test case runs " << s << ".comp";
}

using SelftestGpu = test::GpuTest;

// The cases of `kernels` that `selftest --quick` runs (the table's order).
std::vector<size_t> quick_cases_of(const std::set<std::string>& kernels) {
  std::vector<size_t> out;
  const std::vector<SelftestCaseEntry> table = selftest_cases();
  for (size_t i = 0; i < table.size(); ++i)
    if (table[i].quick && kernels.count(table[i].kernel)) out.push_back(i);
  return out;
}

// A quick run of a few kernels as `tfmatch selftest --quick --kernel ...` makes it: exactly the
// table's quick cases of those kernels, all passed, with the validation state. Every case of every
// kernel passing on this device is KernelCases.MatchTheirCpuReferences (tests/kernels), and the
// whole quick run through the command line is the README's example (DocExamples), so this test
// does not run the whole table a third time.
TEST_F(SelftestGpu, QuickRunOfChosenKernelsRunsTheirQuickCases) {
  const std::set<std::string> chosen = {"residual_map", "gd_update", "correlation_pearson"};
  SelftestOptions options{.quick = true};
  options.kernels.assign(chosen.begin(), chosen.end());
  const SelftestReport report = run_selftest(ctx(), options);
  std::ostringstream table;
  print_selftest_table(table, report);
  std::cout << table.str();
  EXPECT_TRUE(report.passed()) << table.str();
  const std::vector<SelftestCaseEntry> entries = selftest_cases();
  const std::vector<size_t> expected = quick_cases_of(chosen);
  ASSERT_EQ(report.cases.size(), expected.size()) << table.str();
  for (size_t k = 0; k < expected.size(); ++k) {
    const SelftestCase& c = report.cases[k];
    EXPECT_EQ(c.kernel, entries[expected[k]].kernel);
    EXPECT_EQ(c.name, entries[expected[k]].name);
    // (A device without a limit a case needs skips it, saying what; lavapipe runs them all.)
    if (c.status == SelftestStatus::Skipped) {
      EXPECT_EQ(c.detail.rfind("needs ", 0), 0u) << c.kernel << " (" << c.name << "): " << c.detail;
      continue;
    }
    EXPECT_EQ(c.status, SelftestStatus::Pass) << c.kernel << " (" << c.name << "): " << c.detail;
    EXPECT_GT(c.compared, 0u) << c.kernel << " (" << c.name << ") compared nothing";
    EXPECT_LE(c.max_error, c.bound) << c.kernel << " (" << c.name << ")";
  }
  EXPECT_EQ(report.validation, ctx().validation_enabled());
}

// A case whose shared-memory path needs more than the device has is skipped, saying what.
TEST_F(SelftestGpu, CaseBeyondTheSharedMemoryIsSkippedSayingWhatItNeeds) {
  const bool fits = uint64_t(6 * 1500 + 4) * 8 <= ctx().limits().maxComputeSharedMemorySize;
  const std::vector<SelftestCaseEntry> table = selftest_cases();
  bool found = false;
  for (size_t i : quick_cases_of({"assemble_normal_equations"}))
    if (table[i].name.find("N=1500, runs, shared memory") != std::string::npos) {
      found = true;
      const SelftestCase c = run_selftest_case(ctx(), i);
      EXPECT_EQ(c.status, fits ? SelftestStatus::Pass : SelftestStatus::Skipped) << c.detail;
      if (!fits) EXPECT_EQ(c.detail.rfind("needs ", 0), 0u) << c.detail;
    }
  EXPECT_TRUE(found);
}

// Every check can fail: a device value moved by 1 (far above every bound) fails every case, and
// the failure names the element with its device and reference values.
TEST_F(SelftestGpu, PerturbedDeviceValueFailsEveryCase) {
  SelftestOptions options;
  options.quick = true;
  options.perturbation = 1.0;
  const SelftestReport report = run_selftest(ctx(), options);
  ASSERT_FALSE(report.cases.empty());
  for (const SelftestCase& c : report.cases) {
    if (c.status == SelftestStatus::Skipped) continue;
    EXPECT_EQ(c.status, SelftestStatus::Fail) << c.kernel << " (" << c.name << ") passed a perturbed value";
    EXPECT_NE(c.detail.find("device"), std::string::npos) << c.detail;
    EXPECT_NE(c.detail.find("reference"), std::string::npos) << c.detail;
    EXPECT_GT(c.max_error, c.bound) << c.kernel << " (" << c.name << ")";
  }
  EXPECT_FALSE(report.passed());
}

TEST_F(SelftestGpu, SelectsKernelsAndRejectsUnknownNames) {
  SelftestOptions options;
  options.quick = true;
  options.kernels = {"residual_map", "gd_update"};
  const SelftestReport report = run_selftest(ctx(), options);
  ASSERT_FALSE(report.cases.empty());
  for (const SelftestCase& c : report.cases) EXPECT_TRUE(c.kernel == "residual_map" || c.kernel == "gd_update") << c.kernel;
  EXPECT_TRUE(report.passed());
  options.kernels = {"no_such_kernel"};
  EXPECT_THROW(run_selftest(ctx(), options), std::invalid_argument);
}

// The JSON report of `selftest --quick --kernel ...` (a whole quick run is the README's example).
TEST(SelftestCli, QuickJsonListsTheKernelsAndCasesItRan) {
  // The assembly's quick cases include one that needs more shared memory than lavapipe (and
  // NVIDIA's Vulkan drivers) offer: a skipped case, which compares nothing.
  const test::CliResult r =
      test::run_cli("-q selftest --quick --kernel residual_map,gd_update,assemble_normal_equations --json -");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = parse_json(r.output);
  ASSERT_TRUE(j.is_object()) << r.output;
  EXPECT_TRUE(j["passed"].get<bool>());
  EXPECT_TRUE(j["quick"].get<bool>());
  EXPECT_EQ(j["counts"]["fail"].get<int>(), 0);
  EXPECT_FALSE(j["device"].get<std::string>().empty());
  std::set<std::string> kernels;
  for (const auto& k : j["kernels"]) kernels.insert(k.get<std::string>());
  EXPECT_EQ(kernels, (std::set<std::string>{"residual_map", "gd_update", "assemble_normal_equations"}));
  EXPECT_EQ(j["cases"].size(), quick_cases_of(kernels).size());
  EXPECT_EQ(j["counts"]["pass"].get<size_t>() + j["counts"]["skipped"].get<size_t>(), j["cases"].size());
  // The device and driver as the context has them, with the IDs that tell two of one name apart.
  const Context& context = test::context();
  EXPECT_EQ(j["driver"], context.driver_description());
  EXPECT_EQ(j["vendor_id"], context.properties().vendorID);
  EXPECT_EQ(j["device_id"], context.properties().deviceID);
  EXPECT_EQ(j["driver_version"], context.properties().driverVersion);
  int compared_nothing = 0;
  for (const auto& c : j["cases"]) {
    for (const char* key : {"kernel", "wrapper", "case", "status", "max_error", "bound", "compared", "detail", "time_ms"})
      EXPECT_TRUE(c.contains(key)) << key << " missing in " << c.dump();
    EXPECT_TRUE(kernels.count(c["kernel"].get<std::string>())) << c.dump();
    // A case that compared nothing has no error and no bound (null), not zeros.
    if (c["compared"].get<uint64_t>() == 0) {
      EXPECT_TRUE(c["max_error"].is_null() && c["bound"].is_null()) << c.dump();
      ++compared_nothing;
    }
    if (c["status"].get<std::string>() == "skipped") continue;  // a device without a limit the case needs
    EXPECT_EQ(c["status"].get<std::string>(), "pass") << c.dump();
    EXPECT_LE(c["max_error"].get<double>(), c["bound"].get<double>()) << c.dump();
  }
  // Where the device has that much shared memory, nothing here was skipped.
  if (context.limits().maxComputeSharedMemorySize < 72 * 1024) EXPECT_GE(compared_nothing, 1);
}

// A memory budget too small for a case (the user's --max-memory or TFMATCH_MAX_MEMORY) skips it,
// saying so: the device did nothing wrong, so nothing fails.
TEST(SelftestCli, CasesBeyondTheMemoryBudgetAreSkippedNotFailed) {
  const test::CliResult r = test::run_cli("selftest --quick --kernel sparse_prepare", test::kCliTimeout,
                                          {{"TFMATCH_MAX_MEMORY", "16M"}});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("FAIL"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("skipped: needs more memory than the budget: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("TFMATCH_MAX_MEMORY=16M"), std::string::npos) << r.output;
}

// --perturb proves on the device at hand that every check can fail: each case that compares
// fails (exit 1), and the report says the run was perturbed.
TEST(SelftestCli, PerturbMakesEveryComparingCaseFail) {
  const test::CliSplitResult r = test::run_cli_split("-q selftest --quick --kernel residual_map,gd_update --perturb 1 --json -");
  EXPECT_EQ(r.exit_code, 1) << r.errors;
  const nlohmann::json j = nlohmann::json::parse(r.output, nullptr, false);  // stdout: the JSON alone
  ASSERT_TRUE(j.is_object()) << r.output;
  EXPECT_EQ(j["perturbation"], 1.0);
  EXPECT_FALSE(j["passed"].get<bool>());
  int failed = 0;
  for (const auto& c : j["cases"]) {
    if (c["status"] == "skipped") continue;
    EXPECT_EQ(c["status"], "fail") << c.dump();
    ++failed;
  }
  EXPECT_GT(failed, 0);
  const test::CliResult table = test::run_cli("selftest --quick --kernel gd_update --perturb 1");
  EXPECT_EQ(table.exit_code, 1);
  EXPECT_NE(table.output.find("perturbed by 1 (--perturb: every case must fail)"), std::string::npos) << table.output;
  EXPECT_EQ(test::run_cli("selftest --perturb -1").exit_code, 2);
}

TEST(SelftestCli, PrintsAnAlignedTableAndExitsOneOnFailure) {
  const test::CliResult r = test::run_cli("selftest --quick --kernel residual_map");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("kernel"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("max error"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("residual_map"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" 0 failed"), std::string::npos) << r.output;
  // The header's columns line up with the rows': "case" starts where every case name does.
  std::istringstream lines(r.output);
  std::string header, row;
  while (std::getline(lines, header) && header.rfind("kernel", 0) != 0) {
  }
  ASSERT_TRUE(std::getline(lines, row)) << r.output;
  EXPECT_EQ(header.find("case"), row.find_first_not_of(' ', std::string("residual_map").size())) << header << "\n" << row;
  // A misspelt kernel is a usage error (2) before any device starts; a device that is not
  // there is exit 4 (no usable device); neither is a failure of the device (1).
  const test::CliResult bad = test::run_cli("selftest --quick --kernel nope", test::kQuickCliTimeout);
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
  EXPECT_NE(bad.output.find("--kernel: no kernel named 'nope'"), std::string::npos) << bad.output;
  for (const std::string device : {"4294967296", "999", "no-such-gpu-name"}) {
    const test::CliResult none = test::run_cli("selftest --quick --kernel loop_probe --device " + device);
    EXPECT_EQ(none.exit_code, 4) << device << "\n" << none.output;
  }
  const test::CliResult wrapped = test::run_cli("selftest --quick --kernel loop_probe --device 4294967296");
  EXPECT_NE(wrapped.output.find("--device: device index 4294967296 is past"), std::string::npos) << wrapped.output;
}

TEST(VersionCli, PrintsVersionCommitAndBuild) {
  const test::CliResult r = test::run_cli("--version");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(std::string("tfmatch ") + TFMATCH_EXPECTED_VERSION), std::string::npos) << r.output;
  // A short hash (with -dirty for a modified tree) or "unknown" outside a git checkout.
  EXPECT_TRUE(std::regex_search(r.output, std::regex("commit: ([0-9a-f]{7,40}(-dirty)?|unknown)\n"))) << r.output;
  EXPECT_NE(r.output.find("build type: "), std::string::npos) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("Vulkan headers: 1\\.[0-9]+\\.[0-9]+"))) << r.output;
  EXPECT_NE(r.output.find("compiler: "), std::string::npos) << r.output;
}

TEST(DevicesCli, JsonListsAtLeastOneDevice) {
  for (const char* args : {"devices --json -"}) {
    const test::CliResult r = test::run_cli(args);
    EXPECT_EQ(r.exit_code, 0) << args << ": " << r.output;
    const nlohmann::json j = parse_json(r.output);
    ASSERT_TRUE(j.is_object() && j["devices"].is_array()) << args << ": " << r.output;
    ASSERT_GE(j["devices"].size(), 1u);
    const auto& d = j["devices"][0];
    EXPECT_FALSE(d["name"].get<std::string>().empty());
    EXPECT_TRUE(d["compute_queue"].is_boolean());
    EXPECT_GT(d["max_workgroup_invocations"].get<uint64_t>(), 0u);
    EXPECT_TRUE(std::regex_match(d["vulkan"].get<std::string>(), std::regex("1\\.[0-9]+\\.[0-9]+")));
#ifdef TFMATCH_HAVE_CUDA
    EXPECT_EQ(j["cuda"]["built"], true) << r.output;  // the rest: CudaPluginCli.DevicesSaysWhatTheCudaSolversSee
#else
    EXPECT_EQ(j["cuda"], nlohmann::json({{"built", false}})) << r.output;
#endif
  }
  // --floor adds the driver's own cost, in the JSON and as a line of text.
  const test::CliResult floor = test::run_cli("devices --floor --json -");
  EXPECT_EQ(floor.exit_code, 0) << floor.output;
  const nlohmann::json f = parse_json(floor.output)["driver_floor"];
  ASSERT_TRUE(f.is_object()) << floor.output;
  EXPECT_FALSE(f["device"].get<std::string>().empty());
  for (const char* key : {"instance_ms", "device_ms", "teardown_ms"}) EXPECT_GT(f[key].get<double>(), 0.0) << key;
  EXPECT_NEAR(f["total_ms"].get<double>(),
              f["instance_ms"].get<double>() + f["device_ms"].get<double>() + f["teardown_ms"].get<double>(), 1e-9);
  const test::CliResult text = test::run_cli("devices --floor");
  EXPECT_TRUE(std::regex_search(text.output, std::regex("driver floor on .+: instance [0-9.]+ ms \\+ device [0-9.]+ ms "
                                                        "\\+ teardown [0-9.]+ ms = [0-9.]+ ms\n")))
      << text.output;
  test::TempDir dir;
  const test::CliResult r = test::run_cli("devices --json " + (dir / "devices.json"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir / "devices.json");
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  ASSERT_TRUE(j.is_object());
  EXPECT_GE(j["devices"].size(), 1u);
}

}  // namespace
}  // namespace tfm
