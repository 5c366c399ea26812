#!/bin/sh
# Regenerates every timing table of BENCHMARKS.md into bench/results/ (about 25 min on
# the 2-core dev box when nothing else runs; run it on a quiet machine). AP columns come
# from the finished trainings of bench/cpu_protocol_runs.sh (deterministic, any load).
#
# Usage: bench/run_all.sh [path/to/chicktrain]   (from the repository root; default:
# target/release/chicktrain or $CARGO_TARGET_DIR/release/chicktrain, built if missing;
# PYTHON=... picks the interpreter of step 4, default .venv/bin/python)
set -e
CT=${1:-${CARGO_TARGET_DIR:-target}/release/chicktrain}
[ -x "$CT" ] || cargo build --release
R=bench/results
mkdir -p $R
date -u +"started %Y-%m-%dT%H:%MZ on $(nproc) cores: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2)" > $R/machine.txt

# 1. YOLO variants x sizes (30 rows, ~9 min).
"$CT" bench models --variants yolo-n,yolo-s,yolo-n-p45,yolo-n-nopsa,yolo-n-w0.5,yolo-n-m16 \
  --sizes 256,320,416,512,640 --repeats 20 --train-steps 2 --out $R/models_yolo
# 2. Mask R-CNN depths (compact preset) at two sizes (8 rows, ~6 min).
"$CT" bench models --variants mrcnn-r18,mrcnn-r34,mrcnn-r50,mrcnn-r101 \
  --sizes 256,512 --warmup 1 --repeats 5 --train-steps 1 --out $R/models_maskrcnn
# 3. Scene ablation timings on the trained runs (7 rows, ~2 min; AP read from the runs).
if [ -d runs/ablation/cpu_protocol/base ]; then
  "$CT" bench ablation --no-train --out runs/ablation/cpu_protocol
  mkdir -p $R/ablation
  cp runs/ablation/cpu_protocol/bench.* runs/ablation/cpu_protocol/*.png $R/ablation/
fi
# 4. Same-machine references (optional): ultralytics and torchvision from the venv of
#    bench/requirements.txt (python3 -m venv .venv && .venv/bin/pip install -r
#    bench/requirements.txt), or the interpreter named by $PYTHON.
PY=${PYTHON:-.venv/bin/python}
if command -v "$PY" > /dev/null 2>&1; then
  # The speed table (chicktrain, tract, ultralytics / PyTorch, ONNX Runtime; ~5 min).
  PYTHON="$PY" bench/speed_table.sh "$CT" $R/speed > /dev/null || true
  THREADS=$(nproc) RUNS=2 "$PY" tests/fixtures/maskrcnn/bench_torchvision.py \
    50:256,50:512,101:512 > $R/torchvision_maskrcnn.txt 2>&1 || true
else
  echo "skipping the ultralytics / torchvision references: no $PY (see bench/requirements.txt)" >&2
fi
date -u +"finished %Y-%m-%dT%H:%MZ" >> $R/machine.txt
