#!/usr/bin/env bash
# Builds tfmatch and its tests with AddressSanitizer and UndefinedBehaviorSanitizer (GCC, -O1,
# CUDA off) in their own build directory and runs the test suite there, the validation layer on
# as in tools/run-tests.sh. Any out-of-bounds access, use after free, or undefined behaviour
# (signed overflow, misaligned or null access, bad shifts, invalid enum or bool values, ...) in
# tfmatch's code stops its test with a report. Not part of CI: the build takes about 40 minutes on
# 2 cores and the suite runs 2-3x slower (docs/testing.md#sanitizers).
#
#   tools/run-sanitized-tests.sh [CTEST_ARGS...]        e.g. tools/run-sanitized-tests.sh -R Correlat
#
# Environment: TFMATCH_SANITIZE_BUILD (build directory, default build-sanitize).
# Leak checking is off: the Vulkan loader, Mesa and the validation layer keep allocations to the
# process's end that LeakSanitizer would report as tfmatch's. Left out (SANITIZE_EXCLUDE below)
# rather than loosened: tests that hold tfmatch to a peak resident memory, a memory budget or a
# time (they would measure ASan's shadow memory, quarantine and slower code), and the test whose
# child process crashes on purpose (ASan turns its SIGSEGV into an abort with a report).
# Seen on the first run (2026-11-29, GCC 12): the netCDF-4 probe forked a copy of tfmatch while
# the device started on another thread; GCC 12's libasan has no fork handler for its allocator's
# lock, so the child deadlocked. The probe now starts its own program (tfmatch-netcdf4-probe).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${TFMATCH_SANITIZE_BUILD:-$root/build-sanitize}
flags="-O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DTFMATCH_CUDA=OFF \
  -DCMAKE_C_FLAGS="$flags" -DCMAKE_CXX_FLAGS="$flags" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined"
cmake --build "$build" -j"$(nproc)"
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:detect_stack_use_after_return=0
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
SANITIZE_EXCLUDE=${SANITIZE_EXCLUDE:-'AnEnsembleLargerThanTheBudgetStaysWithinIt|GzipBomb|HostsCommandBuffers|Netcdf4Probe\.ACrash|ViewServerLoadTest|ViewLatencyScript|Package\.|View\.Browser'}
ctest --test-dir "$build" --output-on-failure -j"$(nproc)" --timeout 1800 -E "$SANITIZE_EXCLUDE" "$@"
