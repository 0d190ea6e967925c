#!/usr/bin/env bash
# Regenerates the --help blocks of docs/commands.md from a built tfmatch, keeping the prose around
# them: a block opened with ```text help=CMD gets the output of `tfmatch CMD --help`, one opened
# with ```text help that of `tfmatch --help`. The test DocCommands.* fails when a block and the
# program disagree, and names this script.
# Usage: tools/gen-commands-md.sh [TFMATCH]    (default: build/tfmatch)
set -euo pipefail
cd "$(dirname "$0")/.."
tfmatch=${1:-build/tfmatch}
if [ ! -x "$tfmatch" ]; then
  echo "gen-commands-md: no program at $tfmatch (build first, or give its path)" >&2
  exit 1
fi
# Run as `tfmatch` found on PATH, so the usage lines name the program as users type it.
bin=$(mktemp -d)
new=$(mktemp)
trap 'rm -rf "$bin" "$new"' EXIT
ln -s "$(realpath "$tfmatch")" "$bin/tfmatch"
export GEN_COMMANDS_BIN="$bin"
awk '
  in_block && /^```$/ { in_block = 0 }
  in_block { next }
  { print }
  /^```text help(=[a-z0-9-]+)?$/ {
    cmd = "PATH=\"" ENVIRON["GEN_COMMANDS_BIN"] ":$PATH\" tfmatch"
    if (index($0, "=")) cmd = cmd " " substr($0, index($0, "=") + 1)
    cmd = cmd " --help 2>/dev/null"
    n = 0
    while ((cmd | getline line) > 0) { print line; ++n }
    close(cmd)
    if (n == 0) { print "gen-commands-md: `" cmd "` printed nothing" > "/dev/stderr"; failed = 1; exit 1 }
    in_block = 1
  }
  END { if (in_block && !failed) { print "gen-commands-md: a help block is not closed" > "/dev/stderr"; exit 1 } }
' docs/commands.md > "$new"
cat "$new" > docs/commands.md
echo "gen-commands-md: docs/commands.md updated from $tfmatch"
