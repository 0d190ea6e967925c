#!/usr/bin/env bash
# Builds the libFuzzer targets of the hand-written parsers (legacy VTK, VTI, NRRD, .dat, TF XML,
# TF JSON) and of tfmatch's code around the NetCDF, GRIB and PNG libraries with clang + ASan/UBSan
# and runs each for a fixed time, starting from the seeds in tests/fuzz/seeds (and, for netcdf,
# grib and png, files that fuzz_make_seeds writes through the libraries). Exits non-zero when a
# target finds a crash, leak, timeout or huge allocation; the input that did it is left in
# $BUILD/fuzz-artifacts.
#
#   tools/fuzz.sh [SECONDS_PER_TARGET=30] [TARGET...]     e.g. tools/fuzz.sh 60 vti nrrd
#
# Needs clang and libFuzzer: Debian clang-14 and libclang-rt-14-dev (libclang_rt.fuzzer).
# Environment: TFMATCH_FUZZ_BUILD (build directory, default build-fuzz), FUZZ_JOBS (build jobs),
# FUZZ_KEEP_GOING=1 (fork mode: a crash, timeout or out-of-memory is recorded in fuzz-artifacts and
# fuzzing goes on, for long runs over libraries that can abort or hang on malformed input).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
seconds=${1:-30}
[ $# -gt 0 ] && shift
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(vtk_legacy vti nrrd dat tf_xml tf_json netcdf grib png)
build=${TFMATCH_FUZZ_BUILD:-$root/build-fuzz}

cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ -DTFMATCH_FUZZ=ON >/dev/null
cmake --build "$build" -j "${FUZZ_JOBS:-2}" --target "${targets[@]/#/fuzz_}" fuzz_make_seeds
"$build/tests/fuzz/fuzz_make_seeds" "$build/fuzz-seeds"

dict_for() {
  case $1 in
    vtk_legacy) echo vtk.dict ;;
    vti) echo vti.dict ;;
    nrrd) echo nrrd.dict ;;
    tf_xml | tf_json) echo tf.dict ;;
    netcdf) echo netcdf.dict ;;
    grib) echo grib.dict ;;
    png) echo png.dict ;;
    *) echo "" ;;
  esac
}

failed=()
for t in "${targets[@]}"; do
  corpus=$build/fuzz-corpus/$t
  artifacts=$build/fuzz-artifacts
  mkdir -p "$corpus" "$artifacts"
  args=(-max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 -max_len=65536
        -artifact_prefix="$artifacts/$t-" -print_final_stats=1)
  [ "${FUZZ_KEEP_GOING:-0}" = 1 ] && args+=(-fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1)
  dict=$(dict_for "$t")
  [ -n "$dict" ] && args+=(-dict="$root/tests/fuzz/$dict")
  echo "== fuzz_$t for ${seconds}s"
  seeds=()
  for d in "$root/tests/fuzz/seeds/$t" "$build/fuzz-seeds/$t"; do [ -d "$d" ] && seeds+=("$d"); done
  # New inputs go to the first directory (kept between runs); the seeds are read only.
  if ! LSAN_OPTIONS="suppressions=$root/tests/fuzz/lsan.supp:print_suppressions=0" \
      "$build/tests/fuzz/fuzz_$t" "${args[@]}" "$corpus" "${seeds[@]}" 2>"$build/fuzz-$t.log"; then
    failed+=("$t")
    tail -40 "$build/fuzz-$t.log"
  else
    # Fork mode (FUZZ_KEEP_GOING) prints no final stats: its last status line says as much.
    grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$build/fuzz-$t.log" | tr '\n' ' ' ||
      grep -E "^#[0-9]+:" "$build/fuzz-$t.log" | tail -1
    echo
  fi
done

if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz.sh: findings in: ${failed[*]} (inputs in $build/fuzz-artifacts)" >&2
  exit 1
fi
echo "fuzz.sh: no findings in ${targets[*]} (${seconds}s each)"
