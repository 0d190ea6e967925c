#!/usr/bin/env bash
# The checks to run on a machine with a real GPU, in one go: the device report, the conformance
# self-test, the test suite, the paper's solver table (Vulkan, CUDA and CPU solvers side by side)
# and every benchmark, all on the device tfmatch picks (TFMATCH_DEVICE chooses another).
#
#   tools/gpu-check.sh [--parts LIST] [--deadline S] [--pack FILE] [BUILD_DIR [OUT_DIR]]
#                                                   (defaults: all parts, no deadline, build, gpu-check)
#
# Each step writes OUT_DIR/<step>.log (and .json where the command has JSON) and one line to
# OUT_DIR/summary.txt: exit code and seconds; after every step OUT_DIR/targets.md gives issues 28
# and 29's GPU goals against what has run (tools/gpu_targets.py). Every step has a time limit, so
# a hang costs one step, not the run. --deadline S: no step starts later than S seconds after this
# script did, and each step's limit is cut to the time left, so a run inside a device call of fixed
# length (600 s at most) ends on its own, with a line in the summary for every step it skipped.
# --pack FILE: after every step, OUT_DIR without its raw volumes is packed into FILE (.tar.gz,
# replaced whole, never half-written), so a run cut short from outside still brings back
# everything up to its last step, as one file (a device call brings back at most 8 files).
# LIST (comma separated) picks parts, run in the order it names them, so that a machine lent for
# a few minutes takes what matters most first, or takes them in several calls: check (devices,
# self-test, test suite), solvers (the table), bench (assembly, DiffDVR, renderer), bench-long
# (correlation, streaming), startup (a process's fixed cost, the pipeline cache, the phases of
# --json "timings"), e2e (optimize of 41.5 M voxels and correlate of 10 x 1.76 M from process
# start to exit, beside the driver's own floor and a read of the files, tools/e2e_timing.py),
# torch (the PyTorch peer, tools/torch_peer.py, where PyTorch is installed), view (`tfmatch
# view`'s four pictures per camera change at 512² and 1024², tools/view_latency.py);
# solvers-necker and solvers-combustion are the table's GPU rows at one size each, cuda the CUDA
# solvers' tests. "goals" stands for every part that targets.md's goals read, the most telling
# first (goal_parts below; within 540 s the last may be cut).
set -uo pipefail
goal_parts=bench,e2e,torch,bench-long,view,solvers-combustion,cuda,check

parts=check,solvers,bench,bench-long,startup,e2e,torch,view
deadline=""
pack=""
while [ $# -gt 0 ]; do
  case $1 in
    --parts) parts=$2; shift 2 ;;
    --deadline)
      [[ "${2:-}" =~ ^[0-9]+$ ]] || { echo "gpu-check.sh: --deadline takes whole seconds, not '${2:-}'" >&2; exit 2; }
      deadline=$2; shift 2 ;;
    --pack) pack=$(realpath -m "$2"); shift 2 ;;
    --*) echo "gpu-check.sh: unknown option $1" >&2; exit 2 ;;
    *) break ;;
  esac
done
known=,check,solvers,solvers-necker,solvers-combustion,cuda,bench,bench-long,startup,e2e,torch,view,goals,
expanded=""
for part in ${parts//,/ }; do expanded+=",$([ "$part" = goals ] && echo "$goal_parts" || echo "$part")"; done
for part in ${parts//,/ }; do
  [[ "$known" == *",$part,"* ]] || { echo "gpu-check.sh: unknown part '$part' (known: ${known:1:-1})" >&2; exit 2; }
done
parts=${expanded#,}
build=$(realpath "${1:-build}")
out=$(realpath -m "${2:-gpu-check}")
case "$pack" in "$out"/*) echo "gpu-check.sh: the --pack file must lie outside $out" >&2; exit 2 ;; esac
mkdir -p "$out"
tfm=$build/tfmatch
jobs=$(nproc)
gpu_solvers=normal-equations,qp,cgls,gradient-descent,irls,histogram-matching,cuda-normal-equations,cuda-cgls,diffdvr
solvers=$gpu_solvers,eigen-normal-equations,eigen-cgls
# e2e_timing.py writes its 41.5 M-voxel inputs with NumPy: the first python3 that has it (a pyenv
# python3 on PATH may not, where Debian's does).
python=python3
for candidate in python3 /usr/bin/python3; do
  if command -v "$candidate" >/dev/null && "$candidate" -c 'import numpy' 2>/dev/null; then python=$candidate; break; fi
done

packed() {  # the goals' table, then OUT_DIR (without raw volumes) into the --pack file, replaced whole
  # Issues 28 and 29's goals against what has run so far (tools/gpu_targets.py; a failure to read
  # a result is in targets.log and costs no step).
  python3 "$(dirname "$0")/gpu_targets.py" "$out" --json "$out/targets.json" \
    >"$out/targets.md.part" 2>"$out/targets.log" && mv -f "$out/targets.md.part" "$out/targets.md" \
    || rm -f "$out/targets.md.part"
  [ -n "$pack" ] || return 0
  tar -czf "$pack.part" --exclude='*.raw' -C "$(dirname "$out")" "$(basename "$out")" && mv -f "$pack.part" "$pack"
}

step() {  # step NAME LIMIT_S COMMAND...: run COMMAND with a limit, log it, note its exit code
  local name=$1 limit=$2
  shift 2
  if [ -n "$deadline" ]; then
    local left=$((deadline - SECONDS))
    if [ "$left" -lt 5 ]; then
      printf '%-22s skipped: under 5 s left before the --deadline of %d s\n' "$name" "$deadline" | tee -a "$out/summary.txt"
      packed
      return
    fi
    [ "$left" -lt "$limit" ] && limit=$left
  fi
  local start_ms rc
  start_ms=$(date +%s%3N)
  timeout --kill-after=10 "$limit" "$@" >"$out/$name.log" 2>&1
  rc=$?
  local ms=$(($(date +%s%3N) - start_ms))
  printf '%-22s rc=%-4s %4d.%01d s%s\n' "$name" "$rc" $((ms / 1000)) $((ms % 1000 / 100)) \
    "$([ "$rc" = 124 ] && echo "  (hit its ${limit} s limit)")" | tee -a "$out/summary.txt"
  packed
}

part_check() {
  step version 20 "$tfm" --version
  step devices 30 "$tfm" devices --json "$out/devices.json"
  step selftest 120 "$tfm" selftest --json "$out/selftest.json"
  # The tests that need tools of the build machine (cmake scripts over the source tree, nm,
  # a browser) are left to it.
  if command -v ctest >/dev/null; then
    step ctest 240 ctest --test-dir "$build" -j"$jobs" --timeout 120 --output-on-failure \
      -E '^(Package\.|View\.Browser|Layers\.|Embedding\.NoLibrary)'
  else  # no CMake on the machine: the main suite in one process, validation on as under ctest
    step gtest 240 env TFMATCH_VALIDATION=1 "$build/tests/tfmatch_tests" --gtest_brief=1
  fi
}
part_solvers_necker() {
  # The paper's Table 1 sizes: Necker (250x352x20) and Combustion (480x720x120), synthetic pair.
  step solvers-necker 90 "$tfm" solvers --synthetic --size 250x352x20 --solvers "$solvers" \
    --json "$out/solvers-necker.json"
}
part_solvers_combustion() {
  step solvers-combustion 120 "$tfm" solvers --synthetic --size 480x720x120 --solvers "$gpu_solvers" \
    --json "$out/solvers-combustion.json"
}
part_solvers() {
  part_solvers_necker
  part_solvers_combustion
  # At 41.5 M voxels the CPU baselines take minutes: their own step, so a limit cuts only them.
  step solvers-combustion-cpu 120 "$tfm" solvers --synthetic --size 480x720x120 \
    --solvers eigen-normal-equations,eigen-cgls --json "$out/solvers-combustion-cpu.json"
}
part_cuda() {
  # The CUDA solvers are a plugin beside the program (host/solvers/cuda/cuda_backend.h): a bundle
  # that left it behind fails every CUDA step, so say so once, first.
  [ -f "$build/libtfmatch_cuda.so" ] || echo "cuda: no $build/libtfmatch_cuda.so: the CUDA solvers cannot load" \
    | tee -a "$out/summary.txt"
  if command -v ctest >/dev/null; then
    step cuda-tests 120 ctest --test-dir "$build" -j"$jobs" --output-on-failure -R '^Cuda'
  else
    step cuda-tests 120 env TFMATCH_VALIDATION=1 "$build/tests/tfmatch_tests" --gtest_filter='Cuda*'
  fi
}
part_bench() {
  # --lane-voxels: the run modes' lane length (workgroup count), untuned on a GPU so far.
  step bench 120 "$tfm" bench --repeats 3 --lane-voxels 4,8,16,32,64,128,256,1024 --json "$out/bench.json"
  step bench-diffdvr 90 "$tfm" bench-diffdvr --repeat 3 --json "$out/bench-diffdvr.json"
  step bench-render 60 "$tfm" bench-render --repeat 5
}
part_bench_long() {
  step bench-correlate 90 "$tfm" bench-correlate --json "$out/bench-correlate.json"
  # Where comparing pairs stops beating the merge sort on this GPU (spearman <= 128 and kendall
  # <= 64 members compare pairs: shaders/correlation_layout.h; measured on lavapipe only).
  step bench-correlate-pairs 90 "$tfm" bench-correlate --measures spearman,kendall --members 48,64,65,96,128,129,200 \
    --max-values 40000000 --json "$out/bench-correlate-pairs.json"
  step bench-stream 60 "$tfm" bench-stream --voxels 100000000 --dir "${TMPDIR:-/tmp}" --json "$out/bench-stream.json"
  # Issue 28: the whole-volume optimize at 41.5 M voxels within 1.5x one read of its files, both
  # from the disk (bench-stream drops the files' pages from the page cache before each).
  step bench-stream-off 60 "$tfm" bench-stream --voxels 41472000 --stream off --dir "${TMPDIR:-/tmp}" \
    --json "$out/bench-stream-off.json"
}
part_startup() {
  # A process's fixed cost and where a run's time goes (--json "timings"): the demo's 96^3 pair,
  # optimized first with an empty pipeline cache (every pipeline compiled), then twice with the
  # cache the first run left; `devices` (an instance, no device) for the driver's own floor.
  demo=$out/startup-demo
  cache=$out/startup-cache
  rm -rf "$demo" "$cache"
  step startup-demo 60 "$tfm" demo --out "$demo" -q
  for run in cold warm warm-again; do
    step "startup-$run" 60 env TFMATCH_PIPELINE_CACHE="$cache" "$tfm" optimize \
      --ref "$demo/reference_96x96x96_float32.raw" --field "$demo/field_96x96x96_float32.raw" \
      --ref-tf "$demo/reference_tf.json" --out "$out/startup-tf.json" --json "$out/startup-$run.json"
  done
  step startup-devices 30 "$tfm" devices
}
part_e2e() {
  # Issue 28's end-to-end goals (optimize 41.5 M <= 350 ms, correlate 10 x 1.76 M <= 300 ms, files
  # in the page cache) with the driver floor (`devices --floor`) measured in the same run.
  step e2e 240 "$python" "$(dirname "$0")/e2e_timing.py" "$tfm" --runs 5 --dir "${TMPDIR:-/tmp}" \
    --json "$out/e2e.json"
}
part_torch() {
  # What a user would write instead, in PyTorch on the same GPU (tools/torch_peer.py), checked
  # against double-precision NumPy first: the peer figures of the README's GPU tables.
  step torch 180 python3 "$(dirname "$0")/torch_peer.py" --check --json "$out/torch.json"
}
part_view() {
  # The viewer's latency after a camera change from a plain HTTP client (issue 29's goals: four
  # pictures within 40 ms at 512², 120 ms at 1024²), with the server's breakdown per picture.
  for size in 512 1024; do
    step "view-$size" 120 python3 "$(dirname "$0")/view_latency.py" "$tfm" --size "$size" --changes 9 \
      --json "$out/view-$size.json"
  done
}

# The parts in the order LIST names them, so a short device call runs what matters most first.
for part in ${parts//,/ }; do "part_${part//-/_}"; done
