// The self-test runner: selects the cases, checks each one's device needs, runs it, attributes
// validation messages and exceptions to it, and formats the report as a table.
#include "tfmatch/selftest/selftest.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/memory_budget.h"
#include "tfmatch/selftest/selftest_support.h"

namespace tfm {
namespace {

using selftest::CaseList;
using selftest::CaseSpec;
using selftest::Check;

const CaseList& all_cases() {
  static const CaseList cases = [] {
    CaseList list;
    selftest::add_voxel_cases(list);
    selftest::add_sparse_cases(list);
    selftest::add_gd_cases(list);
    selftest::add_irls_cases(list);
    selftest::add_render_cases(list);
    selftest::add_correlation_cases(list);
    selftest::add_device_cases(list);
    return list;
  }();
  return cases;
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// What the case needs of the device that Vulkan 1.2 does not guarantee, or empty.
std::string missing_limit(const Context& ctx, const CaseSpec& spec) {
  const VkPhysicalDeviceLimits& l = ctx.limits();
  auto needs = [](const char* limit, uint64_t want, uint64_t have) {
    return "needs " + std::string(limit) + " >= " + std::to_string(want) + " (device: " + std::to_string(have) + ")";
  };
  const uint32_t invocations = spec.workgroup.x * spec.workgroup.y;
  if (invocations > l.maxComputeWorkGroupInvocations)
    return needs("maxComputeWorkGroupInvocations", invocations, l.maxComputeWorkGroupInvocations);
  if (spec.workgroup.x > l.maxComputeWorkGroupSize[0])
    return needs("maxComputeWorkGroupSize[0]", spec.workgroup.x, l.maxComputeWorkGroupSize[0]);
  if (spec.workgroup.y > l.maxComputeWorkGroupSize[1])
    return needs("maxComputeWorkGroupSize[1]", spec.workgroup.y, l.maxComputeWorkGroupSize[1]);
  if (spec.storage_buffers > l.maxPerStageDescriptorStorageBuffers)
    return needs("maxPerStageDescriptorStorageBuffers", spec.storage_buffers, l.maxPerStageDescriptorStorageBuffers);
  if (spec.storage_buffers > l.maxPerStageResources)
    return needs("maxPerStageResources", spec.storage_buffers, l.maxPerStageResources);
  return {};
}

SelftestCase run_case(Context& ctx, const CaseSpec& spec, double perturbation) {
  SelftestCase c{spec.kernel, spec.wrapper, spec.name};
  const auto t0 = std::chrono::steady_clock::now();
  if (std::string missing = missing_limit(ctx, spec); !missing.empty()) {
    c.status = SelftestStatus::Skipped;
    c.detail = std::move(missing);
    return c;
  }
  Check check(perturbation);
  try {
    spec.run(ctx, check);
    c.max_error = check.worst_error();
    c.bound = check.worst_bound();
    c.compared = check.compared();
    if (!check.skipped().empty()) {
      c.status = SelftestStatus::Skipped;
      c.detail = check.skipped();
    } else if (check.failed() || check.compared() == 0) {
      c.status = SelftestStatus::Fail;
      c.detail = check.failed() ? check.failure() : "nothing was compared";
    }
  } catch (const MemoryBudgetExceeded& e) {
    // The host's memory budget (--max-memory, TFMATCH_MAX_MEMORY) is the user's limit, not the
    // device's failing: the case did not run.
    c.status = SelftestStatus::Skipped;
    c.detail = std::string("needs more memory than the budget: ") + e.what();
  } catch (const std::exception& e) {
    c.status = SelftestStatus::Fail;
    c.detail = std::string("exception: ") + e.what();
  }
  // Anything the validation layer reported while the case ran fails it.
  const std::vector<std::string> messages = ctx.take_validation_messages();
  if (!messages.empty()) {
    c.status = SelftestStatus::Fail;
    std::string text = "validation: " + messages.front();
    if (messages.size() > 1) text += " (and " + std::to_string(messages.size() - 1) + " more)";
    c.detail = c.detail.empty() ? text : text + "; " + c.detail;
  }
  c.time_ms = ms_since(t0);
  return c;
}

std::string hex(uint32_t v, int width) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%0*x", width, v);
  return buf;
}

std::string format_number(double v) {
  if (std::isinf(v)) return "inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

const char* selftest_status_name(SelftestStatus status) {
  switch (status) {
    case SelftestStatus::Pass: return "pass";
    case SelftestStatus::Fail: return "fail";
    case SelftestStatus::Skipped: return "skipped";
  }
  return "?";
}

size_t SelftestReport::count(SelftestStatus status) const {
  return size_t(std::count_if(cases.begin(), cases.end(), [&](const SelftestCase& c) { return c.status == status; }));
}

std::vector<std::string> selftest_kernels() {
  std::vector<std::string> names;
  for (const CaseSpec& spec : all_cases())
    if (std::find(names.begin(), names.end(), spec.kernel) == names.end()) names.push_back(spec.kernel);
  return names;
}

SelftestReport run_selftest(Context& ctx, const SelftestOptions& options, const SelftestProgress& progress) {
  const std::vector<std::string> known = selftest_kernels();
  for (const std::string& k : options.kernels)
    if (std::find(known.begin(), known.end(), k) == known.end()) {
      std::string list;
      for (const std::string& name : known) list += (list.empty() ? "" : ", ") + name;
      throw std::invalid_argument("selftest: no kernel named '" + k + "' (kernels: " + list + ")");
    }
  std::vector<const CaseSpec*> selected;
  for (const CaseSpec& spec : all_cases()) {
    if (options.quick && !spec.quick) continue;
    if (!options.kernels.empty() &&
        std::find(options.kernels.begin(), options.kernels.end(), spec.kernel) == options.kernels.end())
      continue;
    selected.push_back(&spec);
  }

  SelftestReport report;
  const VkPhysicalDeviceProperties& props = ctx.properties();
  report.device = ctx.device_name();
  report.api_version = props.apiVersion;
  report.driver = ctx.driver_description();
  report.vendor_id = props.vendorID;
  report.device_id = props.deviceID;
  report.driver_version = props.driverVersion;
  report.validation = ctx.validation_enabled();
  report.quick = options.quick;
  report.perturbation = options.perturbation;
  // Messages from before the self-test are not any case's doing.
  (void)ctx.take_validation_messages();
  const auto t0 = std::chrono::steady_clock::now();
  for (size_t i = 0; i < selected.size(); ++i) {
    if (progress) progress(i, selected.size(), SelftestCase{selected[i]->kernel, selected[i]->wrapper, selected[i]->name});
    report.cases.push_back(run_case(ctx, *selected[i], options.perturbation));
  }
  report.time_ms = ms_since(t0);
  return report;
}

std::vector<SelftestCaseEntry> selftest_cases() {
  std::vector<SelftestCaseEntry> out;
  for (const CaseSpec& spec : all_cases()) out.push_back({spec.kernel, spec.wrapper, spec.name, spec.quick});
  return out;
}

SelftestCase run_selftest_case(Context& ctx, size_t index, double perturbation) {
  const CaseList& cases = all_cases();
  if (index >= cases.size())
    throw std::out_of_range("selftest: no case " + std::to_string(index) + " (the table has " +
                            std::to_string(cases.size()) + ")");
  (void)ctx.take_validation_messages();  // earlier messages are not this case's doing
  return run_case(ctx, cases[index], perturbation);
}

void print_selftest_table(std::ostream& out, const SelftestReport& report) {
  struct Row {
    std::string kernel, name, error, bound, time, result;
  };
  std::vector<Row> rows{{"kernel", "case", "max error", "bound", "time ms", "result"}};
  for (const SelftestCase& c : report.cases) {
    Row r{c.kernel, c.name, "-", "-", "", selftest_status_name(c.status)};
    if (c.status != SelftestStatus::Skipped || c.compared > 0) {
      r.error = format_number(c.max_error);
      r.bound = format_number(c.bound);
    }
    if (c.status == SelftestStatus::Fail) r.result = "FAIL: " + c.detail;
    if (c.status == SelftestStatus::Skipped) r.result = "skipped: " + c.detail;
    char time[32];
    std::snprintf(time, sizeof time, "%.1f", c.time_ms);
    r.time = time;
    rows.push_back(std::move(r));
  }
  size_t w[5] = {0, 0, 0, 0, 0};
  for (const Row& r : rows) {
    w[0] = std::max(w[0], r.kernel.size());
    w[1] = std::max(w[1], r.name.size());
    w[2] = std::max(w[2], r.error.size());
    w[3] = std::max(w[3], r.bound.size());
    w[4] = std::max(w[4], r.time.size());
  }
  auto pad = [](const std::string& s, size_t width, bool right) {
    const std::string fill(width - s.size(), ' ');
    return right ? fill + s : s + fill;
  };
  out << "device: " << report.device << " (vendor " << hex(report.vendor_id, 4) << ", device "
      << hex(report.device_id, 4) << "); driver: " << report.driver << " (version " << hex(report.driver_version, 8)
      << "); validation " << (report.validation ? "on" : "off");
  if (report.perturbation != 0.0)
    out << "; device values perturbed by " << format_number(report.perturbation) << " (--perturb: every case must fail)";
  out << "\n";
  for (const Row& r : rows)
    out << pad(r.kernel, w[0], false) << "  " << pad(r.name, w[1], false) << "  " << pad(r.error, w[2], true) << "  "
        << pad(r.bound, w[3], true) << "  " << pad(r.time, w[4], true) << "  " << r.result << "\n";
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%.1f", report.time_ms / 1000.0);
  out << "selftest: " << report.count(SelftestStatus::Pass) << " passed, " << report.count(SelftestStatus::Fail)
      << " failed, " << report.count(SelftestStatus::Skipped) << " skipped in " << seconds << " s ("
      << (report.quick ? "quick" : "full") << ")\n";
}

}  // namespace tfm
