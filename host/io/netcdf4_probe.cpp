// netCDF-4 metadata read first in a child process (netcdf4_probe.h).
#include "netcdf4_probe.h"

#include <netcdf.h>
#include <netcdf_mem.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <thread>
#include <vector>

#include "cancellation.h"

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

}  // namespace

bool has_hdf5_signature(std::string_view head) {
  static constexpr char kSignature[8] = {'\x89', 'H', 'D', 'F', '\r', '\n', '\x1a', '\n'};
  for (size_t offset = 0; offset + 8 <= head.size(); offset = offset == 0 ? 512 : offset * 2)
    if (std::memcmp(head.data() + offset, kSignature, 8) == 0) return true;
  return false;
}

void probe_netcdf4_metadata(const std::string& path, std::string_view memory, std::chrono::milliseconds timeout) {
  run_isolated(
      path,
      [&] {
        int id = -1;
        const int status = memory.empty() ? nc_open(path.c_str(), NC_NOWRITE, &id)
                                          : nc_open_mem(path.c_str(), NC_NOWRITE, memory.size(),
                                                        const_cast<char*>(memory.data()), &id);
        if (status == NC_NOERR) {
          walk_group(id, 0);
          nc_close(id);
        }
      },
      timeout);
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
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  for (;;) {
    const pid_t done = waitpid(child, &status, WNOHANG);
    if (done == child) break;
    if (done < 0) return;  // not ours to wait for any more: nothing to conclude
    if (cancel_requested() || std::chrono::steady_clock::now() > deadline) {
      kill(child, SIGKILL);
      waitpid(child, &status, 0);
      check_cancelled();
      throw std::runtime_error(path + ": malformed netCDF-4/HDF5 file: the HDF5 library did not finish reading its "
                               "metadata within " + std::to_string(double(timeout.count()) / 1000.0).substr(0, 4) +
                               " s (it loops on some malformed files); not read");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  if (WIFSIGNALED(status))
    throw std::runtime_error(path + ": malformed netCDF-4/HDF5 file: the HDF5 library crashed reading its metadata (" +
                             strsignal(WTERMSIG(status)) + "); not read");
  // The child ends with _exit(0) whatever netCDF-C says; another status is an abort or a
  // sanitizer's report of a crash (which exits rather than dying of the signal).
  if (WIFEXITED(status) && WEXITSTATUS(status) != 0)
    throw std::runtime_error(path + ": malformed netCDF-4/HDF5 file: the HDF5 library failed reading its metadata "
                             "(the reading process exited with status " + std::to_string(WEXITSTATUS(status)) +
                             "); not read");
}

}  // namespace tfm
