#!/usr/bin/env bash
# One arm of issue 38's negatives measurement: train the quickstart with a share of
# carcass-free renders (data.negatives.empty) and of renders with distractors
# (data.negatives.distractors), equal steps (350: train.epochs=25, pinned since the
# quickstart trains 700), then score it on the home test split,
# both cross-domain sets and the carcass-free photos of bench/negatives/.
#   bench/negatives/share_run.sh CHICKTRAIN OUT SEED EMPTY DISTRACTORS
# (OUT/run is the run folder; OUT/*.json the scores; OUT/negatives.txt the counts.)
# Run from the repository root. Training is deterministic: a loaded box is slower, not different.
set -euo pipefail
ct=$1 out=$2 seed=$3 empty=$4 distr=$5
mkdir -p "$out"
if [ ! -f "$out/run/best.bpk" ]; then
  "$ct" --config configs/quickstart.toml --run-dir "$out/run" --quiet --set train.epochs=25 \
    --set seed="$seed" --set data.negatives.empty="$empty" --set data.negatives.distractors="$distr"
fi
bench/negatives/score.sh "$ct" "$out/run/best.bpk" "$out"
