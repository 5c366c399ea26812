#!/usr/bin/env bash
# One short GPU check for a machine with an NVIDIA GPU (minutes of device time): build with
# the `cuda` feature, smoke-train each model family (YOLO, Mask R-CNN, Mask2Former) on cuda,
# smoke quickstart in bf16 and f16 (train.precision), train the paper protocol of
# yolo_syn1000 and maskrcnn_r50_syn750 for two epochs each, and score one checkpoint on
# cuda and on flex to show the metrics agree (the bf16 one too: checkpoints are f32).
# Prints train img/s beside data_wait_s (seconds an epoch waited for the loader thread:
# near 0 when rendering and loading keep up with the GPU), epoch times and peak GPU
# memory, and the loader's own images/s on the CPU (`bench loader`); fails fast (set -e, a
# time limit per step).
#
#   bash bench/gpu_check.sh [OUT_DIR]        (default runs/gpu_check)
#
# Needs: nvidia-smi, a CUDA driver, cargo. EPOCHS=N changes the protocol epochs (default 2);
# BF16=0 skips the bf16 repeat of the yolo_syn1000 protocol.
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
# Train img/s, seconds waiting for data and epoch seconds of a run, from its metrics.jsonl.
rates() { python3 - "$1" <<'PY'
import json, sys
r = [json.loads(l) for l in open(sys.argv[1] + "/metrics.jsonl")]
print("epochs %d, train img/s %s, data_wait_s %s, train s %s, epoch s %s, loss scale %s" % (
    len(r), [round(x["images_per_s"], 2) for x in r], [round(x.get("data_wait_s", 0), 2) for x in r],
    [round(x["train_time"], 1) for x in r], [round(x["time"], 1) for x in r], [x.get("loss_scale") for x in r]))
PY
}

for cfg in quickstart.toml maskrcnn_r50_syn250.toml mask2former_syn500.toml; do
  log "smoke $cfg on $DEVICE"
  timeout 300 "$BIN" --config "$cfg" --smoke --device "$DEVICE" --run-dir "$OUT/smoke_${cfg%.toml}" | tail -3
  log "smoke_${cfg%.toml}: $(rates "$OUT/smoke_${cfg%.toml}")"
done

for p in bf16 f16; do
  log "smoke quickstart.toml in $p on $DEVICE"
  timeout 300 "$BIN" --config quickstart.toml --smoke --device "$DEVICE" --set train.precision=$p --run-dir "$OUT/smoke_quickstart_$p" | tail -3
  log "smoke_quickstart_$p: $(rates "$OUT/smoke_quickstart_$p")"
done

for cfg in yolo_syn1000.toml maskrcnn_r50_syn750.toml; do
  name=${cfg%.toml}
  log "paper protocol $cfg, $EPOCHS epochs on $DEVICE"
  peak_start "$name"
  timeout 1200 "$BIN" --config "$cfg" --device "$DEVICE" --set train.epochs="$EPOCHS" --run-dir "$OUT/$name" | tail -3
  peak_stop "$name"
  log "$name: $(rates "$OUT/$name")"
done

# What the data side produces on this machine's CPU cores, beside what the GPU consumed
# above (the runs' train img/s): the training loader alone on yolo_syn1000's cached renders.
log "loader alone, yolo_syn1000.toml (every core)"
timeout 300 "$BIN" bench loader --config yolo_syn1000.toml --batches 40 | tee -a "$OUT/report.txt"

# The speed question of train.precision: the same yolo_syn1000 epochs in bf16 (BF16=0 skips).
if [ "${BF16:-1}" = 1 ]; then
  name=yolo_syn1000_bf16
  log "paper protocol yolo_syn1000.toml in bf16, $EPOCHS epochs on $DEVICE"
  peak_start "$name"
  timeout 1200 "$BIN" --config yolo_syn1000.toml --device "$DEVICE" --set train.epochs="$EPOCHS" --set train.precision=bf16 --run-dir "$OUT/$name" | tail -3
  peak_stop "$name"
  log "$name: $(rates "$OUT/$name")"
fi

for run in smoke_quickstart smoke_quickstart_bf16; do
  log "$run/best.bpk scored on $DEVICE and on flex (same weights, same images)"
  CK="$OUT/$run/best.bpk"
  timeout 300 "$BIN" eval --checkpoint "$CK" --split test --device "$DEVICE" --json > "$OUT/eval_gpu_$run.json"
  timeout 300 "$BIN" eval --checkpoint "$CK" --split test --device flex --json > "$OUT/eval_flex_$run.json"
  python3 - "$OUT" "$run" <<'PY' | tee -a "$OUT/report.txt"
import json, sys
o, run = sys.argv[1], sys.argv[2]
a = json.load(open(f"{o}/eval_gpu_{run}.json")); b = json.load(open(f"{o}/eval_flex_{run}.json"))
d = max(abs(x - y) for k in ("bbox", "segm") for x, y in zip(a[k]["stats"], b[k]["stats"]))
print("%s gpu vs flex: max |stat difference| = %.5f (segm AP gpu %.4f, flex %.4f)" % (run, d, a["segm"]["stats"][0], b["segm"]["stats"][0]))
PY
done
log "done: $OUT/report.txt"
