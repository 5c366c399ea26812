#!/bin/sh
# A/B of the vendored burn-flex patch (vendor/burn-flex/PATCH.md): two chicktrain binaries,
# one built without the patch (delete the `[patch.crates-io]` table of Cargo.toml, `cargo
# update -p burn-flex`, build) and one with it, timed in turns (ABAB…) so that the drift of a
# shared machine falls on both alike. Each turn is `bench models` for yolo-n at 256 px: batch-1
# latency (30 runs) and training img/s at batch 8 (4 steps), fresh processes.
#
# Usage: bench/flex_patch_ab.sh UPSTREAM_BIN PATCHED_BIN [ROUNDS=6] [OUT=bench/results/speed/flex_patch_ab_256.csv]
set -e
A=$1; B=$2; N=${3:-6}; OUT=${4:-bench/results/speed/flex_patch_ab_256.csv}
[ -x "$A" ] && [ -x "$B" ] || { echo "usage: $0 UPSTREAM_BIN PATCHED_BIN [ROUNDS] [OUT]" >&2; exit 1; }
T=$(mktemp -d)
echo "binary,round,latency_ms_median,latency_ms_p10,latency_ms_p90,train_img_s,infer_peak_MiB,train_peak_MiB" > "$OUT"
i=1
while [ "$i" -le "$N" ]; do
  for side in upstream patched; do
    if [ "$side" = upstream ]; then bin=$A; else bin=$B; fi
    "$bin" bench models --variants yolo-n --sizes 256 --repeats 30 --train-steps 4 --out "$T/$side$i" --quiet > /dev/null
    echo "$side,$i,$(tail -n 1 "$T/$side$i/bench.csv" | cut -d, -f5-10)" >> "$OUT"
  done
  i=$((i + 1))
done
rm -rf "$T"
cat "$OUT"
