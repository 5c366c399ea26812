#!/usr/bin/env bash
# Scores one checkpoint for issue 38: segm/bbox stats on the home test split and on
# both cross-domain sets (eval --json), and detections per carcass-free photo of
# bench/negatives/ above 0.25 and 0.5 (predict's images.json).
#   bench/negatives/score.sh CHICKTRAIN CHECKPOINT OUT
# Run from the repository root.
set -euo pipefail
ct=$1 ckpt=$2 out=$3
mkdir -p "$out"
"$ct" eval --checkpoint "$ckpt" --split test --json > "$out/home_test.json"
"$ct" eval --checkpoint "$ckpt" --data bench/crossdomain/crossdomain.toml --split test --json > "$out/crossdomain.json"
"$ct" eval --checkpoint "$ckpt" --data bench/crossdomain2/crossdomain2.toml --split test --json > "$out/crossdomain2.json"
bench/negatives/detections.sh "$ct" "$ckpt" "$out"
cat "$out/negatives.txt"
