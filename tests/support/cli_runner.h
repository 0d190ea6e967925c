// Runs the `tfmatch` program as a user would and captures its exit code and output; or in the
// background, to read its output as it comes, send it signals and measure its peak memory.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

namespace tfm::test {

struct CliResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
  uint64_t peak_rss_bytes = 0;
  double seconds = 0;      // from start to exit
  bool timed_out = false;  // killed at the caller's deadline (exit_code then says SIGKILL)
};

// How long run_cli lets a command run by default: longer than the slowest run a test makes
// that way, so that a command that does not end (`view` serving after an option it should have
// refused) fails its test instead of hanging the suite.
constexpr std::chrono::seconds kCliTimeout{600};
// For runs that must end before any work (usage errors, help): seconds on the slowest machine.
constexpr std::chrono::seconds kQuickCliTimeout{60};
using CliEnvironment = std::vector<std::pair<std::string, std::string>>;

// `tfmatch ARGS` started in the background with extra environment variables; stdout and stderr
// together in one pipe. Through `sh -c "exec LAUNCHER tfmatch ..."` (ARGS may quote and redirect):
// the launcher (tests/support/launcher) passes signals on to tfmatch, ends as it did and reports
// its peak memory, which ru_maxrss of a process forked from this one would not tell apart from
// this process's own.
class CliProcess {
 public:
  explicit CliProcess(const std::string& args, const CliEnvironment& env = {}) {
    int fds[2], rss[2];
    // Close-on-exec: a later child (a run_cli while a `view` runs) does not inherit these pipes.
    if (pipe2(fds, O_CLOEXEC) != 0) return;
    if (pipe2(rss, O_CLOEXEC) != 0) {
      close(fds[0]);
      close(fds[1]);
      return;
    }
    start_ = std::chrono::steady_clock::now();
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], 1);
      dup2(fds[1], 2);
      fcntl(rss[1], F_SETFD, 0);  // the launcher's report pipe stays open across exec
      setenv("TFMATCH_LAUNCHER_RSS_FD", std::to_string(rss[1]).c_str(), 1);
      for (const auto& [k, v] : env) setenv(k.c_str(), v.c_str(), 1);
      const std::string cmd = "exec " + std::string(TFMATCH_CLI_LAUNCHER) + " " + TFMATCH_CLI_PATH + " " + args;
      execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    close(fds[1]);
    close(rss[1]);
    fd_ = fds[0];
    rss_fd_ = rss[0];
  }
  ~CliProcess() {
    if (pid_ > 0 && !reaped_) {
      kill(pid_, SIGKILL);  // and tfmatch with the launcher (PR_SET_PDEATHSIG)
      waitpid(pid_, nullptr, 0);
    }
    if (fd_ >= 0) close(fd_);
    if (rss_fd_ >= 0) close(rss_fd_);
  }
  CliProcess(const CliProcess&) = delete;
  CliProcess& operator=(const CliProcess&) = delete;

  // Reads output until it contains `needle` (true), or the output ends or `timeout` passes (false).
  bool wait_for(const std::string& needle, std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (output_.find(needle) == std::string::npos) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0 || !read_some(int(left.count()))) return false;
    }
    return true;
  }
  void signal(int sig) { kill(pid_, sig); }
  // Reads the rest of the output and reaps the process (killing it after `timeout`).
  CliResult finish(std::chrono::milliseconds timeout = std::chrono::seconds(120)) {
    bool timed_out = false;
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (read_some(int(std::max<int64_t>(
        1, std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now()).count())))) {
      if (std::chrono::steady_clock::now() > end) {
        kill(pid_, SIGKILL);
        timed_out = true;
        break;
      }
    }
    int status = 0;
    rusage usage{};
    wait4(pid_, &status, 0, &usage);
    reaped_ = true;
    CliResult r;
    r.timed_out = timed_out;
    r.output = output_;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    r.peak_rss_bytes = launcher_peak_rss();
    // Without the launcher's report (it was killed): the launcher's own, an upper bound.
    if (r.peak_rss_bytes == 0) r.peak_rss_bytes = uint64_t(usage.ru_maxrss) * 1024;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    return r;
  }
  const std::string& output() const { return output_; }

 private:
  // One read of what arrives within `timeout_ms`; false once the output has ended.
  bool read_some(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return true;  // nothing yet: the caller's deadline decides
    char buf[4096];
    const ssize_t n = read(fd_, buf, sizeof buf);
    if (n <= 0) return false;
    output_.append(buf, size_t(n));
    return true;
  }
  // tfmatch's peak resident memory as the launcher reports it after its end; 0 without a report.
  uint64_t launcher_peak_rss() {
    if (rss_fd_ < 0) return 0;
    std::string text;
    char buf[64];
    ssize_t n;
    while ((n = read(rss_fd_, buf, sizeof buf)) > 0) text.append(buf, size_t(n));
    close(rss_fd_);
    rss_fd_ = -1;
    return std::strtoull(text.c_str(), nullptr, 10);
  }
  pid_t pid_ = -1;
  int fd_ = -1, rss_fd_ = -1;
  bool reaped_ = false;
  std::string output_;
  std::chrono::steady_clock::time_point start_;
};

// Any shell `command` run to its end, stdout and stderr together: its exit status (-1 when it did
// not exit normally) and output. For commands that are not a single tfmatch (mpirun, cd && ...).
inline CliResult run_shell(const std::string& command) {
  CliResult r;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buffer[4096];
  for (size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;) r.output.append(buffer, n);
  const int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// `tfmatch ARGS` (through the shell: ARGS may quote and redirect) with extra environment
// variables, run to its end or killed at `timeout`; stdout and stderr together.
inline CliResult run_cli(const std::string& args, std::chrono::milliseconds timeout = kCliTimeout,
                         const CliEnvironment& env = {}) {
  CliProcess p(args, env);
  return p.finish(timeout);
}

// `tfmatch ARGS` with stdout and stderr kept apart: `output` is stdout alone (what `--json -`
// promises to keep to JSON), `errors` is stderr.
struct CliSplitResult {
  int exit_code = -1;
  std::string output, errors;
  bool timed_out = false;
};
inline CliSplitResult run_cli_split(const std::string& args, std::chrono::milliseconds timeout = kCliTimeout) {
  char name[] = "/tmp/tfmatch_stderr_XXXXXX";
  const int fd = mkstemp(name);
  if (fd < 0) return {};
  close(fd);
  const CliResult r = run_cli(args + " 2>" + name, timeout);  // the shell's redirection: stderr to the file
  CliSplitResult out{r.exit_code, r.output, {}, r.timed_out};
  std::ifstream in(name, std::ios::binary);
  out.errors.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  std::remove(name);
  return out;
}

// A child GoogleTest program's output, for a failure message: its "[  SKIPPED ]" markers written
// "[  skipped ]". ctest reports a test whose output holds that marker as skipped
// (gtest_discover_tests' SKIP_REGULAR_EXPRESSION), so a failure that quotes a child's skips would
// pass CI as "Skipped".
inline std::string quoted_test_output(std::string output) {
  const std::string marker = "[  SKIPPED ]";
  for (size_t at = output.find(marker); at != std::string::npos; at = output.find(marker, at + marker.size()))
    output.replace(at, marker.size(), "[  skipped ]");
  return output;
}

// The whole file at `p` (empty when it cannot be read).
inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Every file under `dir`, relative, sorted (what a run left behind).
inline std::vector<std::string> files_under(const std::filesystem::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) out.push_back(e.path().lexically_relative(dir).string());
  std::sort(out.begin(), out.end());
  return out;
}

// A fresh directory under the system temp dir, removed at scope exit.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    path = std::filesystem::temp_directory_path() /
           ("tfmatch-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter()++));
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
  static int& counter() {
    static int c = 0;
    return c;
  }
};

// Whether the dynamic loader's log of a run (LD_DEBUG=libs in its environment: "calling init:
// <path>" for every library it initialised) shows the library file `name` (libnetcdf.so.19).
inline bool loader_log_shows(const std::string& log, const std::string& name) {
  return log.find("calling init: ") != std::string::npos && log.find("/" + name) != std::string::npos;
}

// Writes raw float32 (native byte order): the input files of command-line tests.
inline void write_floats(const std::string& path, const std::vector<float>& v) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 4));
}

}  // namespace tfm::test
