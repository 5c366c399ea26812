#!/usr/bin/env bash
# Detections on the ten carcass-free photos of bench/negatives/ for after_main.sh's runs
# (issue 38 part 2 beside part 3): each arm's best.bpk, predict --conf 0.25 and 0.5,
# counted by bench/negatives/count.py into RESULTS/<arm>_s<S>_negatives.txt, which
# summarize_after_main.py tabulates. Run from the repository root after after_main.sh:
#   bench/selftrain/negatives.sh target/release/chicktrain runs/after_main \
#     bench/results/selftrain/after_main 0 1 2
set -euo pipefail
if [ $# -lt 4 ]; then
  echo "usage: $0 CHICKTRAIN OUT RESULTS SEED..." >&2
  exit 2
fi
BIN=$(realpath "$1") OUT=$2 RESULTS=$3
shift 3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for S in "$@"; do
  for arm in main ctrl xd xd2 fx fx2; do
    ck=$OUT/${arm}_s$S/best.bpk out=$RESULTS/${arm}_s${S}_negatives.txt
    [ -f "$ck" ] && [ ! -f "$out" ] || continue
    for conf in 0.25 0.5; do
      RAYON_NUM_THREADS=${THREADS:-2} "$BIN" predict --checkpoint "$ck" --input bench/negatives \
        --out "$tmp/${arm}_s${S}_$conf" --conf "$conf" > /dev/null
    done
    python3 bench/negatives/count.py "$tmp/${arm}_s${S}_0.25/images.json" \
      "$tmp/${arm}_s${S}_0.5/images.json" > "$out"
  done
done
