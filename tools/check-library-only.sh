#!/usr/bin/env bash
# Builds tfmatch's libraries alone (-DTFMATCH_BUILD_PROGRAM=OFF: no program, viewer or tests, so
# no CLI11 or cpp-httplib), installs them into a temporary prefix and builds and runs the embed
# example (tools/examples/embed) against that package: what an embedder who wants only the
# libraries does (docs/embedding.md). Run by .ci/run after the test suite.
#
#   tools/check-library-only.sh [BUILD_DIR=build-libonly]
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build-libonly}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
jobs=$(nproc)

cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTFMATCH_BUILD_PROGRAM=OFF >/dev/null
cmake --build "$build" -j "$jobs"
if [ -e "$build/tfmatch" ]; then
  echo "check-library-only: $build/tfmatch was built with TFMATCH_BUILD_PROGRAM=OFF" >&2
  exit 1
fi
cmake --install "$build" --prefix "$work/prefix" >/dev/null
for f in lib/cmake/tfmatch/tfmatchConfig.cmake libexec/tfmatch/tfmatch-netcdf4-probe \
  include/tfmatch/kernels/recording.h; do
  if [ ! -e "$work/prefix/$f" ]; then
    echo "check-library-only: $f not installed" >&2
    exit 1
  fi
done
if [ -e "$work/prefix/bin/tfmatch" ]; then
  echo "check-library-only: bin/tfmatch installed without the program" >&2
  exit 1
fi
cmake -S tools/examples/embed -B "$work/embed" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" \
  -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$work/embed" >/dev/null
"$work/embed/embed_example"
echo "check-library-only: libraries built, installed and embedded without the program"
