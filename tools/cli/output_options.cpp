// --json FILE|- and output-extension checks shared by every subcommand.
#include "output_options.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <mutex>
#include <stdexcept>
#include <thread>

#include <fcntl.h>
#include <unistd.h>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch_version.h"  // generated in the build directory (top-level CMakeLists.txt)

namespace tfm::cli {
namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() > suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

const OutputFormat& png_format() {
  static const OutputFormat f{{".png"}, "PNG image"};
  return f;
}
const OutputFormat& json_format() {
  static const OutputFormat f{{".json"}, "JSON document"};
  return f;
}
const OutputFormat& transfer_function_format() {
  // .paraview.json ends in .json: the writer picks the ParaView preset by the longer suffix.
  static const OutputFormat f{{".json", ".xml"}, "transfer function (.json tfmatch table, .xml framework XML or "
                                                 ".paraview.json ParaView preset)"};
  return f;
}
const OutputFormat& field_format() {
  static const OutputFormat f{{".vti", ".raw"}, "field (.vti VTK ImageData or .raw float32)"};
  return f;
}
const OutputFormat& vti_format() {
  static const OutputFormat f{{".vti"}, "VTK ImageData file"};
  return f;
}

bool has_extension(const std::string& path, const std::string& extension) {
  return ends_with(lower(std::filesystem::path(path).filename().string()), extension);
}

// The problem with `path` as a file of `format`, or empty when its name fits.
static std::string output_format_problem(const std::string& path, const OutputFormat& format) {
  for (const std::string& ext : format.extensions)
    if (has_extension(path, ext)) return {};
  std::string names;
  for (const std::string& ext : format.extensions) names += (names.empty() ? "" : " or ") + ext;
  return "'" + path + "' would hold a " + format.name + ": name it " + names;
}

void check_output_format(const std::string& path, const OutputFormat& format, const std::string& role) {
  if (path.empty()) return;
  const std::string problem = output_format_problem(path, format);
  if (!problem.empty()) throw CLI::ValidationError(role, problem);
}

CLI::Validator output_format(const OutputFormat& format, bool allow_stdout) {
  return CLI::Validator(
      [format, allow_stdout](std::string& path) -> std::string {
        return allow_stdout && path == "-" ? std::string() : output_format_problem(path, format);
      },
      "");
}

CLI::Option* add_json_option(CLI::App* sub, std::string& target, const std::string& what) {
  return sub
      ->add_option("--json", target, "Also write " + what + " as JSON to this .json file ('-': to stdout, instead of the text)")
      ->check(output_format(json_format(), /*allow_stdout=*/true))
      ->type_name("FILE|-");
}

JsonOutput::JsonOutput(std::string target) : target_(std::move(target)) {
  if (!to_stdout()) return;
  // At the descriptor, so that printf tables and std::cout text alike go to /dev/null.
  std::cout.flush();
  std::fflush(stdout);
  const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  stdout_fd_ = ::dup(STDOUT_FILENO);
  if (null < 0 || stdout_fd_ < 0 || ::dup2(null, STDOUT_FILENO) < 0)
    throw std::runtime_error(std::string("--json -: cannot set stdout aside: ") + std::strerror(errno));
  ::close(null);
}

JsonOutput::~JsonOutput() {
  if (stdout_fd_ < 0) return;
  std::cout.flush();
  std::fflush(stdout);
  ::dup2(stdout_fd_, STDOUT_FILENO);
  ::close(stdout_fd_);
}

nlohmann::json timings_json() {
  const PhaseTimes t = phase_times();
  nlohmann::json j;
  double counted = 0;
  for (size_t i = 0; i < kPhaseCount; ++i) {
    j[std::string(phase_name(Phase(i))) + "_ms"] = t.seconds[i] * 1e3;
    counted += t.seconds[i];
  }
  j["total_ms"] = t.since_start_s * 1e3;
  j["other_ms"] = (t.since_start_s - counted) * 1e3;
  return j;
}

namespace {
struct RunDevice {
  std::mutex mutex;
  std::string device, driver;
};
RunDevice& run_device() {
  static RunDevice d;
  return d;
}
}  // namespace

void record_run_device(const std::string& device, const std::string& driver) {
  RunDevice& d = run_device();
  const std::lock_guard lock(d.mutex);
  d.device = device;
  d.driver = driver;
}

nlohmann::json environment_json() {
  nlohmann::json j = {
      {"tfmatch", {{"version", TFMATCH_VERSION}, {"commit", TFMATCH_GIT_COMMIT}, {"build_type", TFMATCH_BUILD_TYPE}}},
      {"cpu_threads", std::thread::hardware_concurrency()}};
  RunDevice& d = run_device();
  const std::lock_guard lock(d.mutex);
  if (!d.device.empty()) {
    j["device"] = d.device;
    j["driver"] = d.driver;
  }
  return j;
}

void JsonOutput::write(const nlohmann::json& j) const {
  if (!wanted()) return;
  nlohmann::json out = j;
  if (out.is_object()) {
    out["timings"] = timings_json();
    out["environment"] = environment_json();
  }
  const std::string text = json_text(out, 2) + "\n";
  if (!to_stdout()) return write_file_atomically(target_, text);
  for (size_t done = 0; done < text.size();) {
    const ssize_t n = ::write(stdout_fd_, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw std::runtime_error(std::string("--json -: writing to stdout: ") + std::strerror(errno));
    done += size_t(n);
  }
}

}  // namespace tfm::cli
