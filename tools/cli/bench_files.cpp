// What the file benchmarks share (tools/cli/bench_files.h).
#include "bench_files.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "tfmatch/model/cancellation.h"

namespace tfm::cli {

namespace fs = std::filesystem;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::array<uint64_t, 3> bench_grid(uint64_t voxels) {
  const uint64_t xy = std::max<uint64_t>(1, uint64_t(std::llround(std::cbrt(double(voxels) / 0.8))));
  const uint64_t z = std::max<uint64_t>(1, uint64_t(std::llround(double(voxels) / double(xy * xy))));
  return {xy, xy, z};
}

void write_bench_fields(const fs::path& ref_path, const fs::path& field_path, std::array<uint64_t, 3> d) {
  std::vector<float> wx(d[0]), wy(d[1]), slice_ref(d[0] * d[1]), slice_field(d[0] * d[1]);
  for (uint64_t x = 0; x < d[0]; ++x) wx[x] = float(std::sin(0.02 * double(x)));
  for (uint64_t y = 0; y < d[1]; ++y) wy[y] = float(std::cos(0.013 * double(y)));
  std::ofstream ref(ref_path, std::ios::binary), field(field_path, std::ios::binary);
  if (!ref || !field) throw std::runtime_error(ref_path.parent_path().string() + ": cannot create the benchmark files");
  for (uint64_t z = 0; z < d[2]; ++z) {
    checkpoint("write");
    const float wz = float(0.5 * std::sin(0.05 * double(z)));
    for (uint64_t y = 0; y < d[1]; ++y)
      for (uint64_t x = 0; x < d[0]; ++x) {
        const float v = wx[x] + wy[y] + wz;
        slice_ref[y * d[0] + x] = v;
        slice_field[y * d[0] + x] = 10.0f + 3.0f * v + 0.5f * v * v * v;
      }
    ref.write(reinterpret_cast<const char*>(slice_ref.data()), std::streamsize(slice_ref.size() * sizeof(float)));
    field.write(reinterpret_cast<const char*>(slice_field.data()), std::streamsize(slice_field.size() * sizeof(float)));
    if (!ref || !field) throw std::runtime_error(ref_path.parent_path().string() + ": writing the benchmark files failed (disk full?)");
  }
}

void drop_cached_pages(const fs::path& p) {
  const int fd = ::open(p.c_str(), O_RDONLY);
  if (fd < 0) return;
  ::fdatasync(fd);
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  ::close(fd);
}

double read_files(const std::vector<fs::path>& files) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<char> buffer(size_t(64) << 20);
  for (const fs::path& p : files) {
    const int fd = ::open(p.c_str(), O_RDONLY);
    if (fd < 0) throw std::runtime_error(p.string() + ": cannot open");
    ssize_t n;
    while ((n = ::read(fd, buffer.data(), buffer.size())) > 0) checkpoint("read");
    ::close(fd);
    if (n < 0) throw std::runtime_error(p.string() + ": read failed");
  }
  return seconds_since(t0);
}

ChildRun run_child(const std::vector<std::string>& args, const fs::path& log, const std::string& what) {
  std::vector<char*> argv;
  std::vector<std::string> copy = args;
  for (std::string& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error(what + ": fork failed");
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) ::dup2(fd, 1), ::dup2(fd, 2);
    ::execv(argv[0], argv.data());
    _exit(127);
  }
  ChildRun r;
  int status = 0;
  rusage usage{};
  while (true) {
    const pid_t w = ::wait4(pid, &status, WNOHANG, &usage);
    if (w == pid) break;
    if (w < 0) throw std::runtime_error(what + ": wait4 failed");
    if (cancel_requested()) {
      ::kill(pid, SIGTERM);
      ::wait4(pid, &status, 0, &usage);
      check_cancelled();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  r.seconds = seconds_since(t0);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.peak_rss_bytes = uint64_t(usage.ru_maxrss) * 1024;  // KiB on Linux
  return r;
}

std::string gib(uint64_t bytes) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(2) << double(bytes) / double(uint64_t(1) << 30) << " GiB";
  return os.str();
}

std::string self_path() { return fs::read_symlink("/proc/self/exe").string(); }

std::array<double, 3> load_average() {
  std::array<double, 3> load{-1, -1, -1};
  if (std::FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf %lf %lf", &load[0], &load[1], &load[2]) != 3) load = {-1, -1, -1};
    std::fclose(f);
  }
  return load;
}

}  // namespace tfm::cli
