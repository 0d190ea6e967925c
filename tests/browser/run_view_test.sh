#!/bin/sh
# Runs the real-browser test of `tfmatch view` (view_test.mjs): headless Chromium driven by
# puppeteer-core. Usage: run_view_test.sh PATH/TO/tfmatch
# Exit 77 (ctest: skipped) where node, Chromium or puppeteer-core (npm ci here) is missing.
case $0 in */*) here=${0%/*} ;; *) here=. ;; esac
if [ $# -lt 1 ]; then
  echo "usage: $0 PATH/TO/tfmatch" >&2
  exit 2
fi
if ! command -v node >/dev/null 2>&1; then
  echo "SKIPPED: no node (Debian package nodejs); the browser test of tfmatch view did not run"
  exit 77
fi
exec node "$here/view_test.mjs" "$@"
