#!/usr/bin/env bash
# Few-shot at equal optimiser steps on the Blender cross-domain set (BENCHMARKS.md
# "Transfer"): the 24 train images of fewshot.toml alone against the same 24 plus 400
# renders with half of every batch real (`train.real_fraction = 0.5`), seeds 0-2, the
# same STEPS x EPOCHS optimiser steps of batch 8 and the same augmentation recipe
# (rotation by any angle, vertical flips, scale jitter 0.25) either way. Two `chicktrain
# sweep`s side by side at one thread each (training is deterministic, so the load changes
# the time, not the metrics); each prints its mean ± sample std over the three seeds' test
# splits (72 images per seed; the seed also draws the split) and writes OUT/{real,mix}/ (runs, sweep.md, sweep.csv).
# Rerunning reads finished runs back instead of training them again.
#
#   bench/crossdomain/equal_steps.sh target/release/chicktrain runs/fs_short 16 15    # 240 steps
#   bench/crossdomain/equal_steps.sh target/release/chicktrain runs/fs_long 50 20 \
#       --set train.val_every=4                                                      # 1000 steps
#   bench/crossdomain/equal_steps.sh target/release/chicktrain runs/fs_n1 16 15 \
#       --set data.train_limit=1                            # 1 of the 24 real train images
#
# FEWSHOT_CONFIG=bench/crossdomain/fewshot_maskrcnn.toml runs the same with Mask R-CNN.
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
COMMON=(--config "${FEWSHOT_CONFIG:-bench/crossdomain/fewshot.toml}" --seeds 3 --quiet
  --set "train.steps_per_epoch=$STEPS" --set "train.epochs=$EPOCHS"
  --set train.degrees=180 --set train.flipud=0.5 --set train.scale=0.25 "$@")
RAYON_NUM_THREADS=1 "$BIN" sweep --syn 0 --out "$OUT/real" "${COMMON[@]}" > "$OUT/real.md" &
real=$!
RAYON_NUM_THREADS=1 "$BIN" sweep --syn 400 --out "$OUT/mix" "${COMMON[@]}" \
  --set train.real_fraction=0.5 > "$OUT/mix.md" &
mix=$!
wait "$real"
wait "$mix"
cat "$OUT/real.md" "$OUT/mix.md"
