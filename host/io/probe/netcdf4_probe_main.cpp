// tfmatch-netcdf4-probe: the child process of probe_netcdf4_metadata (host/io/netcdf4_probe.h).
// Reads one netCDF-4 file's metadata as tfmatch would and exits 0 whatever netCDF-C says; a crash
// or an endless loop inside HDF5 happens here, where it costs only this process.
//
//   tfmatch-netcdf4-probe --give-up-after SECONDS [--stdin] -- NAME
//
// NAME is the file, or with --stdin the name the bytes on standard input go by. After SECONDS the
// process ends itself (SIGALRM), so a caller that died before it could kill it leaves nothing
// running. Exit status 2: wrong arguments. Never 127, which the caller takes for "could not run".
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "tfmatch/io/netcdf4_probe.h"

namespace {

int usage() {
  std::fputs("usage: tfmatch-netcdf4-probe --give-up-after SECONDS [--stdin] -- NAME\n", stderr);
  return 2;
}

// All of standard input (an in-memory file the caller wrote).
bool read_all(int fd, std::string& out) {
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = read(fd, buffer, sizeof buffer);
    if (n == 0) return true;
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    out.append(buffer, size_t(n));
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5 || std::strcmp(argv[1], "--give-up-after") != 0) return usage();
  char* end = nullptr;
  const unsigned long seconds = std::strtoul(argv[2], &end, 10);
  if (*argv[2] == '\0' || *end != '\0' || seconds == 0 || seconds > 86400) return usage();
  int next = 3;
  const bool from_stdin = std::strcmp(argv[next], "--stdin") == 0;
  if (from_stdin) ++next;
  if (argc != next + 2 || std::strcmp(argv[next], "--") != 0) return usage();
  const std::string name = argv[next + 1];
  alarm(unsigned(seconds));
  if (!from_stdin) {
    tfm::walk_netcdf4_metadata(name);
    return 0;
  }
  std::string bytes;
  if (!read_all(0, bytes)) {
    std::fprintf(stderr, "tfmatch-netcdf4-probe: %s: cannot read standard input: %s\n", name.c_str(), std::strerror(errno));
    return 3;
  }
  if (!bytes.empty()) tfm::walk_netcdf4_metadata(name, bytes);
  return 0;
}
