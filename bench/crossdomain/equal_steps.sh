#!/usr/bin/env bash
# Few-shot at equal optimiser steps on the Blender cross-domain set (BENCHMARKS.md
# "Transfer"): the 24 train images of fewshot.toml alone against the same 24 plus 400
# renders with half of every batch real (`train.real_fraction = 0.5`), seeds 0-2, the
# same STEPS x EPOCHS optimiser steps of batch 8 and the same augmentation recipe
# (rotation by any angle, vertical flips, scale jitter 0.25) either way. Each seed's pair
# trains side by side at one thread each (training is deterministic, so the load changes
# the time, not the metrics). Prints mean ± sample std of the test split's stats (72
# images per seed; the seed also draws the split).
#
#   bench/crossdomain/equal_steps.sh target/release/chicktrain runs/fs_short 16 15    # 240 steps
#   bench/crossdomain/equal_steps.sh target/release/chicktrain runs/fs_long 50 20 \
#       --set train.val_every=4                                                      # 1000 steps
#
# Time on the 2-core box: ~40 min for 240 steps, ~2 h for 1000 steps (three seeds).
set -euo pipefail
if [ $# -lt 4 ]; then
  echo "usage: $0 CHICKTRAIN OUT STEPS_PER_EPOCH EPOCHS [--set key=value ...]" >&2
  exit 2
fi
BIN=$1 OUT=$2 STEPS=$3 EPOCHS=$4
shift 4
mkdir -p "$OUT"
COMMON=(--set "train.steps_per_epoch=$STEPS" --set "train.epochs=$EPOCHS"
  --set train.degrees=180 --set train.flipud=0.5 --set train.scale=0.25 "$@")
for s in 0 1 2; do
  if [ ! -e "$OUT/real_s$s/test.json" ]; then
    RAYON_NUM_THREADS=1 "$BIN" --config bench/crossdomain/fewshot.toml --run-dir "$OUT/real_s$s" \
      --set seed=$s "${COMMON[@]}" > "$OUT/real_s$s.log" 2>&1 &
  fi
  if [ ! -e "$OUT/mix_s$s/test.json" ]; then
    RAYON_NUM_THREADS=1 "$BIN" --config bench/crossdomain/fewshot.toml --run-dir "$OUT/mix_s$s" \
      --set seed=$s --set data.synthetic=400 --set train.real_fraction=0.5 "${COMMON[@]}" \
      > "$OUT/mix_s$s.log" 2>&1 &
  fi
  wait
done
python3 - "$OUT" <<'EOF'
import json, statistics, sys
out = sys.argv[1]
names = ["AP", "AP50", "AP75"]
print("| run | runs | bbox AP | segm AP | segm AP50 | segm AP75 |")
print("|---|---|---|---|---|---|")
for run, label in [("real", "24 real alone"), ("mix", "24 real + 400 renders, half of each batch real")]:
    rows = []
    for s in range(3):
        try:
            t = json.load(open(f"{out}/{run}_s{s}/test.json"))
        except FileNotFoundError:
            continue
        rows.append([t["bbox"]["stats"][0]] + t["segm"]["stats"][:3])
    if not rows:
        continue
    cells = []
    for k in range(4):
        v = [r[k] for r in rows]
        sd = statistics.stdev(v) if len(v) > 1 else float("nan")
        cells.append(f"{statistics.mean(v):.3f} ± {sd:.3f}")
    print(f"| {label} | {len(rows)} | " + " | ".join(cells) + " |")
EOF
