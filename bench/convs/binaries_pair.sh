#!/bin/bash
# Two chicktrain binaries' convolutions and models on one quiet box, one after the other,
# plus ONNX Runtime on the same convolution shapes (issue 37). For a change that is a build
# setting rather than code (the `gemm` crate's AVX-512 kernels), the two binaries are the
# comparison: OLD and NEW run the same commands, alternately, in one session.
#   1. `bench convs` at batch 1 (256 and 640 px) and batch 8 (256 px, YOLO11n-seg), OLD
#      then NEW, then both once more (the medians of both runs are compared);
#   2. `bench/convs/ort_convs.py` on NEW's convs.csv: ONNX Runtime per shape (PYTHON names
#      the interpreter of a venv with bench/requirements.txt; skipped if it is missing);
#   3. `bench models --variants yolo-n` (batch-1 latency, training img/s at batch 8) at
#      256, 320 and 640 px, OLD then NEW;
#   4. bench/convs/binaries_pair.py: the ratio table OUT/pair.md.
# About 8 minutes on 2 cores. Run it with nothing else on the machine.
#   bench/convs/binaries_pair.sh OLD_BINARY NEW_BINARY OUT
set -euo pipefail
if [ $# -ne 3 ]; then echo "usage: $0 OLD_BINARY NEW_BINARY OUT" >&2; exit 2; fi
OLD=$(realpath "$1"); NEW=$(realpath "$2"); mkdir -p "$3"; OUT=$(realpath "$3")
PY=${PYTHON:-.venv/bin/python}
cd "$(dirname "$0")/../.."
{
  date -u +"started %Y-%m-%dT%H:%M:%SZ on $(nproc) cores: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2)"
  echo "flags: $(grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' | grep -E '^(avx2|fma|avx512f|avx512_vnni|avx512bw)$' | tr '\n' ' ')"
  echo "old: $OLD ($(sha256sum "$OLD" | cut -c1-12))"
  echo "new: $NEW ($(sha256sum "$NEW" | cut -c1-12))"
  echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
} > "$OUT/machine.txt"
export RAYON_NUM_THREADS=2
for round in 1 2; do
  for side in old new; do
    BIN=$OLD; [ $side = new ] && BIN=$NEW
    "$BIN" bench convs --sizes 256,640 --out "$OUT/convs_b1_${side}_$round" > /dev/null
    "$BIN" bench convs --sizes 256 --batch 8 --models yolo11n-seg --out "$OUT/convs_b8_${side}_$round" > /dev/null
    echo "convs round $round $side done, load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT/machine.txt"
  done
done
if command -v "$PY" > /dev/null 2>&1; then
  "$PY" bench/convs/ort_convs.py "$OUT/convs_b1_new_1/convs.csv" --threads 2 --runs 20 > /dev/null
  "$PY" bench/convs/ort_convs.py "$OUT/convs_b8_new_1/convs.csv" --threads 2 --runs 10 > /dev/null
  echo "onnx runtime done, load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT/machine.txt"
else
  echo "no $PY: ONNX Runtime column skipped" | tee -a "$OUT/machine.txt" >&2
fi
for side in old new; do
  BIN=$OLD; [ $side = new ] && BIN=$NEW
  "$BIN" bench models --variants yolo-n --sizes 256,320,640 --repeats 10 --train-steps 5 \
    --out "$OUT/models_$side" --quiet > /dev/null
  echo "models $side done, load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT/machine.txt"
done
date -u +"finished %Y-%m-%dT%H:%M:%SZ" >> "$OUT/machine.txt"
python3 bench/convs/binaries_pair.py "$OUT" | tee "$OUT/pair.md"
