// What tfmatch does about netCDF-4 files before netCDF-C reads them in-process: their metadata is
// parsed by HDF5, whose internals tfmatch cannot check first, and fuzzing found malformed files
// on which HDF5 (Debian's 1.10.8) crashes (a segmentation fault in H5HG_read) or loops without
// end while netCDF-C reads variables' dimension scales. So a netCDF-4 file is first opened in a
// child process that reads every group's, variable's, dimension's and attribute's metadata; only
// when that child ends normally does the caller read the file itself.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <string_view>

namespace tfm {

// True when `head` (the first bytes of a file) starts with the HDF5 signature at one of the
// offsets HDF5 allows (0, 512, 1024, ...; `head` is what the caller has, at least 8 bytes).
bool has_hdf5_signature(std::string_view head);

// Opens `path` (or, when `memory` is not empty, those bytes, named `path` in messages) with
// netCDF-C in a child process and walks all its metadata there. Throws std::runtime_error
// "<path>: malformed netCDF-4/HDF5 file: ..." when the child is killed by a signal (a crash
// inside HDF5), exits with a non-zero status (an abort, a sanitizer's crash report) or runs
// longer than `timeout` (then it is killed), and checks the cancellation
// flag (host/model/cancellation.h) while it waits. An error netCDF-C reports in the child is left
// for the caller's own open to report. Returns quietly on success.
void probe_netcdf4_metadata(const std::string& path, std::string_view memory = {},
                            std::chrono::milliseconds timeout = std::chrono::seconds(30));

// The mechanism: runs `work` in a child process (fork, then _exit(0) after it) and throws, as
// above, when the child dies of a signal or outlives `timeout`; `path` starts the messages.
void run_isolated(const std::string& path, const std::function<void()>& work, std::chrono::milliseconds timeout);

}  // namespace tfm
