#!/usr/bin/env bash
# The newcomer's one command on a fresh Debian machine: install the Debian packages tfmatch
# needs, build it, and run the demo. `--deps-only` stops after installing (used by CI);
# `--no-demo` stops after building. Other arguments go to `tfmatch demo`.
set -euo pipefail
cd "$(dirname "$0")/.."

deps_only=0 demo=1 demo_args=()
for arg in "$@"; do
  case "$arg" in
    --deps-only) deps_only=1 ;;
    --no-demo) demo=0 ;;
    *) demo_args+=("$arg") ;;
  esac
done

sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
packages=$(grep -v '^#' tools/debian-packages.txt | tr '\n' ' ')
$sudo apt-get update
$sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $packages
# The browser test's driver (tests/browser: puppeteer-core, no browser download) needs Node.js and
# npm; Debian's are used where the machine has none of its own.
if ! command -v npm >/dev/null; then
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends nodejs npm
fi
npm ci --prefix tests/browser --no-audit --no-fund --loglevel=error
[ "$deps_only" -eq 1 ] && exit 0

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build -j"$(nproc)"
[ "$demo" -eq 1 ] && ./build/tfmatch demo --out tfmatch-demo "${demo_args[@]}"
exit 0
