// netCDF-4 metadata read first in a child process (netcdf4_probe.h).
#include "tfmatch/io/netcdf4_probe.h"

#include <netcdf.h>
#include <netcdf_mem.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <map>
#include <stdexcept>
#include <thread>
#include <tuple>
#include <vector>

#include "tfmatch/model/cancellation.h"

namespace tfm {
namespace {

// Reads what netCDF-C reads when tfmatch describes or loads a file: every group, its dimensions,
// variables (with their dimension ids, which is where HDF5 follows dimension scales) and
// attributes. Runs in the child; returns normally whatever netCDF-C says.
void walk_group(int group, int depth) {
  if (depth > 64) return;
  int ndims = 0, nvars = 0, natts = 0, unlimited = 0;
  if (nc_inq(group, &ndims, &nvars, &natts, &unlimited) != NC_NOERR) return;
  char name[NC_MAX_NAME + 1];
  int dim_count = 0;
  if (nc_inq_dimids(group, &dim_count, nullptr, 1) == NC_NOERR && dim_count > 0) {
    std::vector<int> dims(static_cast<size_t>(dim_count));
    if (nc_inq_dimids(group, nullptr, dims.data(), 1) == NC_NOERR)
      for (int d : dims) {
        size_t length = 0;
        nc_inq_dim(group, d, name, &length);
      }
  }
  for (int a = 0; a < natts; ++a) {
    nc_type type = 0;
    size_t length = 0;
    if (nc_inq_attname(group, NC_GLOBAL, a, name) == NC_NOERR) nc_inq_att(group, NC_GLOBAL, name, &type, &length);
  }
  for (int v = 0; v < nvars; ++v) {
    nc_type type = 0;
    int var_dims = 0, var_atts = 0;
    if (nc_inq_var(group, v, name, &type, &var_dims, nullptr, &var_atts) != NC_NOERR) continue;
    std::vector<int> dimids(size_t(std::max(var_dims, 0)) + 1);
    nc_inq_vardimid(group, v, dimids.data());
    for (int a = 0; a < var_atts; ++a) {
      nc_type att_type = 0;
      size_t length = 0;
      if (nc_inq_attname(group, v, a, name) == NC_NOERR) nc_inq_att(group, v, name, &att_type, &length);
    }
  }
  int groups = 0;
  if (nc_inq_grps(group, &groups, nullptr) == NC_NOERR && groups > 0) {
    std::vector<int> ids(static_cast<size_t>(groups));
    if (nc_inq_grps(group, nullptr, ids.data()) == NC_NOERR)
      for (int g : ids) walk_group(g, depth + 1);
  }
}

constexpr const char* kProbeProgram = "tfmatch-netcdf4-probe";

// Waits for `child`, checking the cancellation flag and the deadline every 2 ms; kills and reaps
// it when either comes first (then throws). Returns its wait status; 0 when it is not ours to wait
// for any more (nothing to conclude).
int wait_for_child(const std::string& path, pid_t child, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  for (;;) {
    const pid_t done = waitpid(child, &status, WNOHANG);
    if (done == child) return status;
    if (done < 0 && errno != EINTR) return 0;
    if (cancel_requested() || std::chrono::steady_clock::now() > deadline) {
      kill(child, SIGKILL);
      while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
      }
      check_cancelled();
      throw std::runtime_error(path + ": malformed netCDF-4/HDF5 file: the HDF5 library did not finish reading its "
                               "metadata within " + std::to_string(double(timeout.count()) / 1000.0).substr(0, 4) +
                               " s (it loops on some malformed files); not read");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

// Throws unless the child ended normally with status 0.
void check_child_status(const std::string& path, int status) {
  if (WIFSIGNALED(status)) {
    // Ctrl-C reaches the child too (same process group): that is the caller's interruption.
    check_cancelled();
    throw std::runtime_error(path + ": malformed netCDF-4/HDF5 file: the HDF5 library crashed reading its metadata (" +
                             strsignal(WTERMSIG(status)) + "); not read");
  }
  // The child ends with status 0 whatever netCDF-C says; another status is an abort or a
  // sanitizer's report of a crash (which exits rather than dying of the signal).
  if (WIFEXITED(status) && WEXITSTATUS(status) != 0)
    throw std::runtime_error(path + ": malformed netCDF-4/HDF5 file: the HDF5 library failed reading its metadata "
                             "(the reading process exited with status " + std::to_string(WEXITSTATUS(status)) +
                             "); not read");
}

// The probe's verdict on each file probed in this process, by the file as it was then (device,
// inode, size, modification time): empty when it passed, else the error. A command that opens
// one file several times (several variables or time steps of it, one per --field; a slab reader,
// then a whole load) starts one child, not one per open, and a malformed file that made HDF5 loop
// costs one timeout, not one per open. A file changed since is probed again.
using FileIdentity = std::tuple<dev_t, ino_t, off_t, time_t, long>;
std::mutex g_verdicts_mutex;
std::map<FileIdentity, std::string> g_verdicts;  // guarded by g_verdicts_mutex

bool identify(const std::string& path, FileIdentity& identity) {
  struct stat st {};
  if (stat(path.c_str(), &st) != 0) return false;
  identity = {st.st_dev, st.st_ino, st.st_size, st.st_mtim.tv_sec, st.st_mtim.tv_nsec};
  return true;
}

}  // namespace

bool has_hdf5_signature(std::string_view head) {
  static constexpr char kSignature[8] = {'\x89', 'H', 'D', 'F', '\r', '\n', '\x1a', '\n'};
  for (size_t offset = 0; offset + 8 <= head.size(); offset = offset == 0 ? 512 : offset * 2)
    if (std::memcmp(head.data() + offset, kSignature, 8) == 0) return true;
  return false;
}

void walk_netcdf4_metadata(const std::string& path, std::string_view memory) {
  int id = -1;
  const int status = memory.empty() ? nc_open(path.c_str(), NC_NOWRITE, &id)
                                    : nc_open_mem(path.c_str(), NC_NOWRITE, memory.size(),
                                                  const_cast<char*>(memory.data()), &id);
  if (status != NC_NOERR) return;
  walk_group(id, 0);
  nc_close(id);
}

std::string netcdf4_probe_program() {
  if (const char* chosen = std::getenv("TFMATCH_NETCDF4_PROBE"); chosen && *chosen) return chosen;
  std::vector<std::filesystem::path> candidates;
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  if (!error) {
    candidates.push_back(self.parent_path() / kProbeProgram);
    candidates.push_back(self.parent_path().parent_path() / "libexec" / "tfmatch" / kProbeProgram);
  }
#ifdef TFM_NETCDF4_PROBE_INSTALLED
  candidates.emplace_back(TFM_NETCDF4_PROBE_INSTALLED);
#endif
  for (const std::filesystem::path& candidate : candidates)
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  return {};
}

namespace {

// The probe itself: its program where there is one, else a forked child.
void probe_uncached(const std::string& path, std::string_view memory, std::chrono::milliseconds timeout) {
  if (const std::string program = netcdf4_probe_program(); !program.empty()) {
    // The program gives up by itself a little after the timeout: a caller killed before it could
    // kill the child leaves no process behind looping on a malformed file.
    const auto give_up_s = std::chrono::duration_cast<std::chrono::seconds>(timeout).count() + 5;
    std::vector<std::string> arguments{"--give-up-after", std::to_string(give_up_s)};
    if (!memory.empty()) arguments.emplace_back("--stdin");
    arguments.insert(arguments.end(), {"--", path});
    if (run_program_isolated(path, program, arguments, memory, timeout)) return;
  }
  // The fork: netCDF-C is loaded here first (its functions load it on first use), so that the
  // child of this threaded process (a device starting beside the read) runs no dlopen, which
  // failed there about one time in three under mpirun ("libnetcdf.so.19 could not be loaded",
  // or a crash reported as a malformed file).
  nc_strerror(NC_NOERR);
  run_isolated(path, [&] { walk_netcdf4_metadata(path, memory); }, timeout);
}

}  // namespace

void probe_netcdf4_metadata(const std::string& path, std::string_view memory, std::chrono::milliseconds timeout) {
  FileIdentity identity;
  const bool known = memory.empty() && identify(path, identity);
  if (known) {
    const std::lock_guard lock(g_verdicts_mutex);
    if (const auto v = g_verdicts.find(identity); v != g_verdicts.end()) {
      if (v->second.empty()) return;
      throw std::runtime_error(v->second);
    }
  }
  std::string verdict;
  try {
    probe_uncached(path, memory, timeout);
  } catch (const std::runtime_error& e) {  // Cancelled is not one: a cancelled probe has no verdict
    verdict = e.what();
    if (verdict.empty()) verdict = path + ": malformed netCDF-4/HDF5 file";
  }
  if (known) {
    const std::lock_guard lock(g_verdicts_mutex);
    g_verdicts.emplace(identity, verdict);
  }
  if (!verdict.empty()) throw std::runtime_error(verdict);
}

bool run_program_isolated(const std::string& path, const std::string& program, const std::vector<std::string>& arguments,
                          std::string_view input, std::chrono::milliseconds timeout) {
  // The input as an anonymous in-memory file (seekable, as netCDF-C's memory reading needs it
  // whole): written before the child starts, so nothing waits on a pipe.
  int input_fd = -1;
  if (!input.empty()) {
    input_fd = memfd_create("tfmatch-probe-input", MFD_CLOEXEC);
    if (input_fd >= 0 && input_fd < 3) {  // keep clear of 0-2, which the child's actions rebind
      const int moved = fcntl(input_fd, F_DUPFD_CLOEXEC, 3);
      close(input_fd);
      input_fd = moved;
    }
    if (input_fd < 0) return false;
    for (size_t written = 0; written < input.size();) {
      const ssize_t n = write(input_fd, input.data() + written, input.size() - written);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        close(input_fd);
        return false;
      }
      written += size_t(n);
    }
    lseek(input_fd, 0, SEEK_SET);
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (input_fd >= 0)
    posix_spawn_file_actions_adddup2(&actions, input_fd, 0);
  else
    posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  // The child starts with no signal blocked and every signal's default action (the caller may
  // ignore SIGPIPE, or block SIGINT on this thread): Ctrl-C in a terminal stops it with the caller.
  posix_spawnattr_t attributes;
  posix_spawnattr_init(&attributes);
  sigset_t none, all;
  sigemptyset(&none);
  sigfillset(&all);
  posix_spawnattr_setsigmask(&attributes, &none);
  posix_spawnattr_setsigdefault(&attributes, &all);
  posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  std::vector<char*> argv{const_cast<char*>(program.c_str())};
  for (const std::string& argument : arguments) argv.push_back(const_cast<char*>(argument.c_str()));
  argv.push_back(nullptr);
  pid_t child = -1;
  const int spawned = posix_spawn(&child, program.c_str(), &actions, &attributes, argv.data(), environ);
  posix_spawnattr_destroy(&attributes);
  posix_spawn_file_actions_destroy(&actions);
  if (input_fd >= 0) close(input_fd);
  if (spawned != 0) return false;
  const int status = wait_for_child(path, child, timeout);
  // 127: the program was started but could not run (the dynamic loader missing a library, or
  // exec failing after the spawn); the probe program itself never exits with it.
  if (WIFEXITED(status) && WEXITSTATUS(status) == 127) return false;
  check_child_status(path, status);
  return true;
}

void run_isolated(const std::string& path, const std::function<void()>& work, std::chrono::milliseconds timeout) {
  const pid_t child = fork();
  if (child < 0) return;  // no process to spare: the caller reads the file as before
  if (child == 0) {
    // Only `work` runs here, then _exit: no destructors, no atexit handlers of the parent's
    // libraries (the Vulkan driver's among them).
    work();
    _exit(0);
  }
  check_child_status(path, wait_for_child(path, child, timeout));
}

}  // namespace tfm
