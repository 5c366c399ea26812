#!/bin/sh
# The speed table of BENCHMARKS.md ("Speed against ultralytics and ONNX Runtime"), every
# column from one run on one machine: chicktrain's yolo-n on flex (latency, training
# img/s, peak RSS), the same weights' ONNX export in tract, ultralytics YOLO11n-seg in
# PyTorch (latency, training, peak RSS), and ONNX Runtime on both ONNX files (chicktrain's
# export and ultralytics' own). About 5 min on the 2-core dev box; run it on a quiet machine.
#
# Usage: bench/speed_table.sh [path/to/chicktrain] [OUT]   (from the repository root;
# PYTHON=... names the interpreter of the venv of bench/requirements.txt, default
# .venv/bin/python; OUT defaults to bench/results/speed)
set -e
CT=${1:-${CARGO_TARGET_DIR:-target}/release/chicktrain}
R=${2:-bench/results/speed}
PY=${PYTHON:-.venv/bin/python}
[ -x "$CT" ] || cargo build --release
command -v "$PY" > /dev/null 2>&1 || { echo "no $PY: python3 -m venv .venv && .venv/bin/pip install -r bench/requirements.txt" >&2; exit 1; }
SIZES=256,320,640
mkdir -p "$R/onnx"
{
  date -u +"started %Y-%m-%dT%H:%MZ on $(nproc) cores: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2)"
  echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
} > "$R/machine.txt"

# 1. chicktrain yolo-n on flex: batch-1 latency (BatchNorm folded), training img/s at
#    batch 8, peak RSS of a fresh process per row.
"$CT" bench models --variants yolo-n --sizes $SIZES --repeats 10 --train-steps 5 --out "$R/models" --quiet
# 2. The same weights on flex and in tract, one process; writes chicktrain's ONNX files.
"$CT" bench engines --variants yolo-n --sizes $SIZES --repeats 10 --threads 2 --save-onnx "$R/onnx" > "$R/engines.txt"
# 3. ultralytics in PyTorch (2 threads), each measurement in a fresh process; writes
#    ultralytics' own ONNX export per size.
"$PY" bench/ultralytics_yolo.py 256 320 640 --onnx-dir "$R/onnx" > "$R/ultralytics_yolo.txt"
# 4. ONNX Runtime (2 intra-op threads) on every ONNX file.
"$PY" bench/onnx_latency.py "$R"/onnx/*.onnx --runs 20 --threads 2 > "$R/onnx_runtime.txt"
rm -rf "$R/onnx"
{
  echo "load average at end: $(cut -d' ' -f1-3 /proc/loadavg)"
  date -u +"finished %Y-%m-%dT%H:%MZ"
} >> "$R/machine.txt"
cat "$R/machine.txt" "$R/engines.txt" "$R/ultralytics_yolo.txt" "$R/onnx_runtime.txt"
