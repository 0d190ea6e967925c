#!/usr/bin/env bash
# Packs a build for a lent GPU machine in one step: ../shared/gpu/bundle.sh (the programs, the
# libraries, the validation layer, optionally ../shared/data) plus the build's files it does not
# carry — the CUDA solvers' plugin (libtfmatch_cuda.so, without which every CUDA step fails) and
# the netCDF-4 probe — into OUT/extra/, and prints the device call that puts them back beside
# `tfmatch` before running tools/gpu-check.sh.
#
#   tools/gpu-pack.sh [--with-data] [BUILD_DIR [OUT_DIR]]        (defaults: build .gpu)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
data=(); [ "${1:-}" = "--with-data" ] && { data=(--with-data); shift; }
build=$(realpath "${1:-$root/build}")
out=$(realpath -m "${2:-$root/.gpu}")
bundle=$root/../shared/gpu/bundle.sh
[ -f "$bundle" ] || { echo "gpu-pack.sh: no $bundle (it comes with ../shared)" >&2; exit 1; }
[ -x "$build/tfmatch" ] || { echo "gpu-pack.sh: no $build/tfmatch: build first" >&2; exit 1; }
case "$out" in
  "$root"/*) mkdir -p "$out"; git -C "$root" check-ignore -q "$out" ||
    { echo "gpu-pack.sh: $out must be ignored by git (echo /${out#"$root"/}/ >> .git/info/exclude)" >&2; exit 1; } ;;
esac
bash "$bundle" "${data[@]}" "$build" "$out"
rm -rf "$out/extra" && mkdir -p "$out/extra"
for f in libtfmatch_cuda.so tfmatch-netcdf4-probe; do
  [ -f "$build/$f" ] && cp "$build/$f" "$out/extra/"
done
grep -q '^TFMATCH_CUDA:BOOL=ON' "$build/CMakeCache.txt" && [ ! -f "$out/extra/libtfmatch_cuda.so" ] &&
  { echo "gpu-pack.sh: the build has TFMATCH_CUDA on but no libtfmatch_cuda.so" >&2; exit 1; }
du -sh "$out" | awk '{print "carried: " $1 " (at most 64 MiB)"}'
rel=${out#"$root"/}
echo "device call: carry [\"$rel\"], timeout_s 600, command:"
echo "  bash $rel/run.sh 'cp $rel/extra/* \"\$TFMATCH_BUILD\"/; tools/gpu-check.sh --parts LIST --deadline 540 --pack \"\$OUT/gpu.tar.gz\" \"\$TFMATCH_BUILD\" /tmp/gpu-check'"
