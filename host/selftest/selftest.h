// Conformance self-test: runs every compute kernel against its double-precision CPU reference on
// awkward sizes (1, 13, one past a workgroup, NaNs, values off range and on TF nodes, fields split
// into chunks) on one device, for people who test portability across Vulkan drivers.
#pragma once

#include <cstdint>
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"

namespace tfm {

struct SelftestOptions {
  // Only the small cases (seconds on lavapipe); otherwise also the large sizes.
  bool quick = false;
  // Run only the kernels named here (shader names, as selftest_kernels() lists them); all if empty.
  std::vector<std::string> kernels;
  // Added to the first device value every case compares: a value above the case's bound must
  // make it fail. Tests use it to prove each check can fail; 0 for real runs.
  double perturbation = 0.0;
};

enum class SelftestStatus { Pass, Fail, Skipped };
const char* selftest_status_name(SelftestStatus status);  // "pass", "fail", "skipped"

struct SelftestCase {
  std::string kernel;   // shader name (shaders/<kernel>.comp)
  std::string wrapper;  // the C++ class (or function) of kernels/ that drives it
  std::string name;     // what the case exercises: size, path, NaNs, chunks, ...
  SelftestStatus status = SelftestStatus::Pass;
  // The compared element nearest to (or furthest past) its bound: its |device - reference| and
  // its bound. Bounds are absolute; where a kernel's bound is relative the case scales it first.
  double max_error = 0.0;
  double bound = 0.0;
  uint64_t compared = 0;  // values compared (0: max_error and bound mean nothing)
  // Why a case failed (first failing element: where, expected, actual; or the validation
  // message or exception) or was skipped ("needs ..."); empty when it passed.
  std::string detail;
  double time_ms = 0.0;  // wall time of the case: setup, device work and CPU reference
};

struct SelftestReport {
  std::string device;
  std::string driver;  // the driver's name and version: "llvmpipe Mesa 22.3.6, Vulkan 1.3.230"
  // The device's PCI vendor and device IDs and its driver version (vendor-specific encoding), as
  // VkPhysicalDeviceProperties has them: what tells two devices of one name apart.
  uint32_t vendor_id = 0, device_id = 0, driver_version = 0;
  uint32_t api_version = 0;
  bool validation = false;  // the Khronos validation layer was on (any message fails the case)
  bool quick = false;
  double perturbation = 0.0;  // SelftestOptions::perturbation: non-zero, every comparing case must fail
  std::vector<SelftestCase> cases;
  double time_ms = 0.0;

  size_t count(SelftestStatus status) const;
  bool passed() const { return count(SelftestStatus::Fail) == 0; }
};

// Called before each case runs (index among the cases that will run, their number, the case).
using SelftestProgress = std::function<void(size_t index, size_t total, const SelftestCase& starting)>;

// Every kernel the self-test covers (shader names), in report order.
std::vector<std::string> selftest_kernels();

// Runs the cases on `ctx`. A case fails when an element exceeds its bound, the kernel throws, or
// the validation layer reports anything while it runs; it is skipped when the device lacks a
// limit or feature it needs, or the process's memory budget is too small for it (the detail says
// which). Throws std::invalid_argument when
// options.kernels names a kernel selftest_kernels() does not list.
SelftestReport run_selftest(Context& ctx, const SelftestOptions& options = {},
                            const SelftestProgress& progress = nullptr);

// The case table itself, for the GoogleTest suite, which runs every case (quick or not) as one
// test (tests/kernels/test_kernel_cases.cpp): a case is written once, here, for both. Each entry's
// kernel, wrapper, name and whether it is quick; run_selftest_case runs entry `index` as
// run_selftest runs it (device limits, skips, bounds, validation messages and exceptions).
struct SelftestCaseEntry {
  std::string kernel, wrapper, name;
  bool quick = true;
};
std::vector<SelftestCaseEntry> selftest_cases();
SelftestCase run_selftest_case(Context& ctx, size_t index, double perturbation = 0.0);

// The report as a device line, an aligned table (kernel, case, max error, bound, time, result:
// "pass", "FAIL: <first failing element>" or "skipped: needs ...") and a summary line.
void print_selftest_table(std::ostream& out, const SelftestReport& report);

}  // namespace tfm
