#!/usr/bin/env bash
# One short GPU check for a machine with an NVIDIA GPU (minutes of device time): build with
# the `cuda` feature, smoke-train each model family on cuda, train the paper protocol of
# yolo_syn1000 and maskrcnn_r50_syn750 for two epochs each, and score one checkpoint on
# cuda and on flex to show the metrics agree. Prints train img/s, epoch times and peak GPU
# memory; fails fast (set -e, a time limit per step).
#
#   bash bench/gpu_check.sh [OUT_DIR]        (default runs/gpu_check)
#
# Needs: nvidia-smi, a CUDA driver, cargo. EPOCHS=N changes the protocol epochs (default 2).
# FEATURE=wgpu DEVICE=wgpu runs the same check through wgpu (Vulkan) instead: the `cuda`
# feature's build downloads an LLVM bundle (cubecl-llvm's build script), so on a machine
# without network access only `wgpu` builds.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-runs/gpu_check}
EPOCHS=${EPOCHS:-2}
FEATURE=${FEATURE:-cuda}
DEVICE=${DEVICE:-cuda}
mkdir -p "$OUT"
log() { echo "[gpu_check $(date +%T)] $*" | tee -a "$OUT/report.txt"; }

nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | tee "$OUT/gpu.txt"
log "building with --features $FEATURE"
cargo build --release --features "$FEATURE" 2>&1 | tail -3
BIN=target/release/chicktrain
[ -n "${CARGO_TARGET_DIR:-}" ] && BIN="$CARGO_TARGET_DIR/release/chicktrain"

# Peak GPU memory of a step: sample nvidia-smi every 0.5 s in the background.
peak_start() { (while true; do nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits; sleep 0.5; done) > "$OUT/mem_$1.txt" 2>/dev/null & PEAK_PID=$!; }
peak_stop() { kill "$PEAK_PID" 2>/dev/null || true; wait "$PEAK_PID" 2>/dev/null || true; log "$1: peak GPU memory $(sort -n "$OUT/mem_$1.txt" | tail -1) MiB"; }
# Mean train img/s and epoch seconds of a run, from its metrics.jsonl.
rates() { python3 - "$1" <<'PY'
import json, sys
r = [json.loads(l) for l in open(sys.argv[1] + "/metrics.jsonl")]
print("epochs %d, train img/s %s, epoch s %s" % (len(r), [round(x["images_per_s"], 2) for x in r], [round(x["time"], 1) for x in r]))
PY
}

for cfg in quickstart.toml maskrcnn_r50_syn250.toml; do
  log "smoke $cfg on $DEVICE"
  timeout 300 "$BIN" --config "$cfg" --smoke --device "$DEVICE" --run-dir "$OUT/smoke_${cfg%.toml}" | tail -3
done

for cfg in yolo_syn1000.toml maskrcnn_r50_syn750.toml; do
  name=${cfg%.toml}
  log "paper protocol $cfg, $EPOCHS epochs on $DEVICE"
  peak_start "$name"
  timeout 1200 "$BIN" --config "$cfg" --device "$DEVICE" --set train.epochs="$EPOCHS" --run-dir "$OUT/$name" | tail -3
  peak_stop "$name"
  log "$name: $(rates "$OUT/$name")"
done

log "one checkpoint scored on $DEVICE and on flex (same weights, same images)"
CK="$OUT/smoke_quickstart/best.bpk"
"$BIN" eval --checkpoint "$CK" --split test --device "$DEVICE" --json > "$OUT/eval_gpu.json"
"$BIN" eval --checkpoint "$CK" --split test --device flex --json > "$OUT/eval_flex.json"
python3 - "$OUT" <<'PY' | tee -a "$OUT/report.txt"
import json, sys
a = json.load(open(sys.argv[1] + "/eval_gpu.json")); b = json.load(open(sys.argv[1] + "/eval_flex.json"))
d = max(abs(x - y) for k in ("bbox", "segm") for x, y in zip(a[k]["stats"], b[k]["stats"]))
print("gpu vs flex: max |stat difference| = %.5f (segm AP gpu %.4f, flex %.4f)" % (d, a["segm"]["stats"][0], b["segm"]["stats"][0]))
PY
log "done: $OUT/report.txt"
