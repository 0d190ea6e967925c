// What tfmatch does about netCDF-4 files before netCDF-C reads them in-process: their metadata is
// parsed by HDF5, whose internals tfmatch cannot check first, and fuzzing found malformed files
// on which HDF5 (Debian's 1.10.8) crashes (a segmentation fault in H5HG_read) or loops without
// end while netCDF-C reads variables' dimension scales. So a netCDF-4 file is first opened in a
// child process that reads every group's, variable's, dimension's and attribute's metadata; only
// when that child ends normally does the caller read the file itself.
//
// The child is a program of its own, `tfmatch-netcdf4-probe` (host/io/probe/), started with
// posix_spawn: a fresh process shares no lock with the caller's threads. (A forked copy of the
// caller inherits every lock another thread held at the fork, a driver's, an allocator's,
// HDF5's own, and hangs on the first it needs: seen with GCC 12's AddressSanitizer while the
// device started on another thread.) Where that program cannot be found or started, the probe
// falls back to a forked child (run_isolated), as safe as the caller's libraries are across fork.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

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
// for the caller's own open to report. Returns quietly on success. A file (not `memory`) is probed
// once per process while its size and modification time stay the same: a later call gives the
// first one's verdict (quiet, or the same error at once).
void probe_netcdf4_metadata(const std::string& path, std::string_view memory = {},
                            std::chrono::milliseconds timeout = std::chrono::seconds(30));

// What the child does: opens `path` (or the bytes `memory`) and reads every group's dimensions,
// variables (with their dimension ids: where HDF5 follows dimension scales) and attributes, as
// loading and `info` read them. Returns normally whatever netCDF-C says. In-process: only a
// child calls it.
void walk_netcdf4_metadata(const std::string& path, std::string_view memory = {});

// The probe program's path: $TFMATCH_NETCDF4_PROBE when set; else the first that exists of
// `tfmatch-netcdf4-probe` beside the running program, in ../libexec/tfmatch/ from it (an
// installed `tfmatch`), where this build put it, where it is installed. Empty when none exists.
std::string netcdf4_probe_program();

// The mechanisms, `path` starting their messages. run_program_isolated starts `program` with
// `arguments` (argv[1]...), `input` as its standard input (an anonymous in-memory file; empty:
// /dev/null) and its standard output discarded, and returns false, having run nothing, when it
// cannot start it; run_isolated runs `work` in a forked child (then _exit(0)). Both throw as
// above when the child dies of a signal, exits non-zero or outlives `timeout`.
bool run_program_isolated(const std::string& path, const std::string& program, const std::vector<std::string>& arguments,
                          std::string_view input, std::chrono::milliseconds timeout);
void run_isolated(const std::string& path, const std::function<void()>& work, std::chrono::milliseconds timeout);

}  // namespace tfm
