#!/usr/bin/env bash
# Detections of one checkpoint on the ten carcass-free photos of bench/negatives/ (issue
# 38): predict --conf 0.25 and 0.5 into OUT/pred_0.25 and OUT/pred_0.5, counted by
# count.py into OUT/negatives.txt. score.sh and bench/selftrain/after_main.sh call it.
#   bench/negatives/detections.sh CHICKTRAIN CHECKPOINT OUT
# Run from the repository root.
set -euo pipefail
ct=$1 ckpt=$2 out=$3
mkdir -p "$out"
for conf in 0.25 0.5; do
  "$ct" predict --checkpoint "$ckpt" --input bench/negatives --out "$out/pred_$conf" --conf "$conf" > /dev/null
done
python3 bench/negatives/count.py "$out/pred_0.25/images.json" "$out/pred_0.5/images.json" > "$out/negatives.txt"
