#!/bin/sh
# Two chicktrain binaries timed in turns (OLD, NEW, OLD, NEW, …) so that the drift of the
# machine falls on both alike: each turn is a fresh `bench models --variants yolo-n` at the
# given sizes, batch-1 latency (30 runs, median) and training img/s at batch 8 (4 steps).
# For changes no single process can hold both sides of (a build setting, the allocator's
# parameters set in `main`). Prints the CSV, then per size the median over rounds of each
# side and their ratio (bench/models_ab.py). LABELS names the two sides in the CSV's
# `binary` column (default "old new"; bench/flex_patch_ab.sh passes "upstream patched").
#
# Usage: bench/models_ab.sh OLD_BIN NEW_BIN [ROUNDS=4] [SIZES=256,320,640] [OUT=models_ab.csv]
set -e
A=$1; B=$2; N=${3:-4}; SIZES=${4:-256,320,640}; OUT=${5:-models_ab.csv}
LABELS=${LABELS:-old new}
[ -x "$A" ] && [ -x "$B" ] || { echo "usage: $0 OLD_BIN NEW_BIN [ROUNDS] [SIZES] [OUT]" >&2; exit 1; }
T=$(mktemp -d)
echo "binary,round,size,latency_ms_median,latency_ms_p10,latency_ms_p90,train_img_s,infer_peak_MiB,train_peak_MiB" > "$OUT"
i=1
while [ "$i" -le "$N" ]; do
  for side in $LABELS; do
    if [ "$side" = "${LABELS%% *}" ]; then bin=$A; else bin=$B; fi
    "$bin" bench models --variants yolo-n --sizes "$SIZES" --repeats 30 --train-steps 4 --out "$T/$side$i" --quiet > /dev/null
    tail -n +2 "$T/$side$i/bench.csv" | cut -d, -f2,5-10 | sed "s/^/$side,$i,/" >> "$OUT"
  done
  i=$((i + 1))
done
rm -rf "$T"
cat "$OUT"
python3 "$(dirname "$0")/models_ab.py" "$OUT"
