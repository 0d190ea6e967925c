// What the file benchmarks (bench-stream, bench-mpi) share: generated raw fields on disk, timed
// reads, the page cache, and child runs of this program with their wall time and peak memory.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_timing.h"  // seconds_since

namespace tfm::cli {

// A grid of about `voxels` voxels, x = y = 1.25 z.
std::array<uint64_t, 3> bench_grid(uint64_t voxels);

// Writes the two fields z-slice by z-slice: ref = smooth waves in x, y and z; field a monotone
// remap of it, so the fit is meaningful. Throws std::runtime_error naming the directory.
void write_bench_fields(const std::filesystem::path& ref_path, const std::filesystem::path& field_path,
                        std::array<uint64_t, 3> dims);

// Flushes a file and drops its pages from the page cache, so the next read comes from the disk.
void drop_cached_pages(const std::filesystem::path& p);

// Reads every byte of the files once (64 MiB at a time); returns the seconds taken.
double read_files(const std::vector<std::filesystem::path>& files);

struct ChildRun {
  int exit_code = -1;
  double seconds = 0.0;
  uint64_t peak_rss_bytes = 0;  // the largest of the child and the descendants it waited for
};

// Runs `argv` (argv[0] a path) with stdout and stderr to `log`, waiting for it; an interrupt
// ends it too (SIGTERM) and then throws Cancelled. `what` names the benchmark in errors.
ChildRun run_child(const std::vector<std::string>& argv, const std::filesystem::path& log, const std::string& what);
// This program's own path (/proc/self/exe).
std::string self_path();

// "1.25 GiB".
std::string gib(uint64_t bytes);

// The load average of the last 1, 5 and 15 minutes (-1 when unknown).
std::array<double, 3> load_average();

}  // namespace tfm::cli
