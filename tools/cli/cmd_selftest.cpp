// `tfmatch selftest`: every kernel against its double-precision CPU reference on the chosen device
// (host/selftest/selftest.h), as a table or JSON; exit 1 when any case fails.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>

#include "cli.h"
#include "output_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/selftest/selftest.h"

namespace tfm::cli {
namespace {

struct SelftestArgs {
  bool quick = false;
  bool no_validation = false;
  std::string json;
  std::vector<std::string> kernels;
  double perturbation = 0.0;
};

// A non-finite error (NaN read back, say) becomes null: JSON has no infinity.
nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

nlohmann::json report_json(const SelftestReport& r) {
  nlohmann::json cases = nlohmann::json::array();
  for (const SelftestCase& c : r.cases)
    cases.push_back({{"kernel", c.kernel},
                     {"wrapper", c.wrapper},
                     {"case", c.name},
                     {"status", selftest_status_name(c.status)},
                     // Nothing compared (a skipped case): no error and no bound, not zeros.
                     {"max_error", c.compared ? number(c.max_error) : nlohmann::json()},
                     {"bound", c.compared ? number(c.bound) : nlohmann::json()},
                     {"compared", c.compared},
                     {"detail", c.detail},
                     {"time_ms", c.time_ms}});
  nlohmann::json kernels = nlohmann::json::array();
  for (const SelftestCase& c : r.cases)
    if (std::find(kernels.begin(), kernels.end(), c.kernel) == kernels.end()) kernels.push_back(c.kernel);
  return {{"tfmatch", environment_json()["tfmatch"]},  // as every JSON's environment names it
          {"device", r.device},
          {"driver", r.driver},
          {"vendor_id", r.vendor_id},
          {"device_id", r.device_id},
          {"driver_version", r.driver_version},
          {"vulkan",
           std::to_string(VK_API_VERSION_MAJOR(r.api_version)) + "." + std::to_string(VK_API_VERSION_MINOR(r.api_version)) +
               "." + std::to_string(VK_API_VERSION_PATCH(r.api_version))},
          {"validation", r.validation},
          {"quick", r.quick},
          {"perturbation", r.perturbation},
          {"passed", r.passed()},
          {"counts",
           {{"pass", r.count(SelftestStatus::Pass)},
            {"fail", r.count(SelftestStatus::Fail)},
            {"skipped", r.count(SelftestStatus::Skipped)}}},
          {"time_ms", r.time_ms},
          {"kernels", kernels},
          {"cases", cases}};
}

int run_selftest_command(const SelftestArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  FilePlan().output(json.file(), "--json").check();
  auto ctx = make_context(!a.no_validation);
  SelftestOptions options;
  options.quick = a.quick;
  options.kernels = a.kernels;
  options.perturbation = a.perturbation;
  // The case being run (a full run takes tens of seconds on a CPU device): an updating line on a
  // terminal, periodic lines in a log.
  std::unique_ptr<Progress> progress;
  SelftestReport report = run_selftest(*ctx, options, [&progress](size_t i, size_t total, const SelftestCase& c) {
    if (!progress) progress = std::make_unique<Progress>("selftest", total);
    progress->set_label("selftest " + c.kernel + ": " + c.name);
    progress->update(i);
  });
  progress.reset();
  json.write(report_json(report));
  if (json.to_stdout()) {
    if (!globals().quiet || !report.passed()) {
      // The table's last line, and every failure, on stderr: stdout is the JSON alone.
      for (const SelftestCase& c : report.cases)
        if (c.status == SelftestStatus::Fail)
          std::cerr << "FAIL " << c.kernel << " (" << c.name << "): " << c.detail << "\n";
      std::cerr << "selftest: " << report.count(SelftestStatus::Pass) << " passed, "
                << report.count(SelftestStatus::Fail) << " failed, " << report.count(SelftestStatus::Skipped)
                << " skipped on " << report.device << "\n";
    }
  } else {
    if (!globals().quiet || !report.passed()) print_selftest_table(std::cout, report);
    if (!globals().quiet && !a.json.empty()) std::cout << "wrote " << a.json << "\n";
  }
  return report.passed() ? 0 : 1;
}

CommandRegistration reg(95, [](CLI::App& app) {
  auto args = std::make_shared<SelftestArgs>();
  auto* sub = app.add_subcommand(
      "selftest", "Run every kernel against its double-precision CPU reference on awkward sizes on the chosen device "
                  "(the Khronos validation layer on where installed; any message fails the case); exit 1 on a failure");
  sub->add_flag("--quick", args->quick, "Small sizes only (seconds on lavapipe)");
  add_json_option(sub, args->json, "the report");
  // Checked as the command line is, before any device starts: a misspelt name is a usage error
  // (exit 2), never a failure the device is blamed for (exit 1).
  sub->add_option("--kernel", args->kernels, "Run only these kernels (shader names; repeat or comma-separate)")
      ->delimiter(',')
      ->check(CLI::Validator(
          [](std::string& name) -> std::string {
            const std::vector<std::string> known = selftest_kernels();
            if (std::find(known.begin(), known.end(), name) != known.end()) return "";
            std::string list;
            for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
            return "no kernel named '" + name + "' (kernels: " + list + ")";
          },
          "KERNEL"));
  sub->add_option("--perturb", args->perturbation,
                  "Add this to the first device value each case compares, to prove on this device that every "
                  "check can fail: with a value past the bounds (1) every case that compares must FAIL (exit 1)")
      ->check(CLI::Range(0.0, 1e6));
  sub->add_flag("--no-validation", args->no_validation,
                "Do not turn the validation layer on by default (--validation or TFMATCH_VALIDATION=1 still do)");
  sub->callback([args] { exit_code() = run_selftest_command(*args); });
});

}  // namespace
}  // namespace tfm::cli
