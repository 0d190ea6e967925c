#!/bin/sh
# Runs one real-browser test (view_test.mjs: `tfmatch view`; report_test.mjs: the report pages) in
# headless Chromium driven by puppeteer-core. Usage: run_browser_test.sh SCRIPT.mjs PATH/TO/tfmatch
# Exit 77 (ctest: skipped) where node, Chromium or puppeteer-core (npm ci here) is missing.
case $0 in */*) here=${0%/*} ;; *) here=. ;; esac
if [ $# -lt 2 ]; then
  echo "usage: $0 SCRIPT.mjs PATH/TO/tfmatch" >&2
  exit 2
fi
script=$1
shift
if ! command -v node >/dev/null 2>&1; then
  echo "SKIPPED: no node (Debian package nodejs); the browser test $script did not run"
  exit 77
fi
exec node "$here/$script" "$@"
