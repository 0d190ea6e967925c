#!/usr/bin/env bash
# Builds tfmatch and runs the whole test suite (GoogleTest through ctest, one process per test,
# Khronos validation on: any validation message fails its test).
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)" --timeout 600 "$@"
