#!/usr/bin/env bash
# Behaviour identity of the experiment runner (issue 40): tiny runs of the three studies
# with one binary — `sweep --smoke` (2 counts x 2 seeds, then --no-train with a third
# count), `bench transfer` (2 variants x 2 seeds scored on a 3-image proxy set, then
# --no-train with a third variant) and `bench ablation --train-only` (2 variants) — all at
# 64 px, 2 optimiser steps, one thread. Compare two recordings with
#
#   bench/redesign_studies_identity.sh BIN DIR
#   bench/redesign_identity.sh compare DIR_A DIR_B
#
# Wall-clock columns the compare does not mask: `train_seconds` (runs.csv) and
# `train_minutes` (sweep.csv) of the sweep.
set -euo pipefail
[ $# = 2 ] || { echo "usage: $0 BIN DIR" >&2; exit 2; }
bin=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
[ -x "$bin" ] || { echo "not an executable: $1" >&2; exit 2; }
mkdir -p "$2/stdout"
cd "$2"
export RAYON_NUM_THREADS=1
tiny=(--set 'data.cache="cache"' --set data.image_size=64 --set data.crop=64
    --set data.real.count=4 --set train.epochs=1 --set train.batch=2
    --set train.steps_per_epoch=2)
"$bin" sweep --config quickstart.toml --syn 0,2 --seeds 2 --smoke "${tiny[@]}" \
    --out runs/sweep --quiet >stdout/sweep.txt
"$bin" sweep --config quickstart.toml --syn 0,2,4 --seeds 2 --smoke "${tiny[@]}" \
    --out runs/sweep --quiet --no-train >stdout/sweep_notrain.txt
printf 'name = "external"\nseed = 7\n[data]\nsplit = [0.0, 0.0]\nimage_size = 64\ncrop = 64\ncache = "cache"\n[data.real]\nkind = "proxy"\ncount = 3\n' >external.toml
"$bin" bench transfer --config quickstart.toml --data-eval external.toml --seeds 2 \
    --variants base,no-fliplr "${tiny[@]}" --set data.synthetic=0 --out runs/transfer \
    --quiet >stdout/transfer.txt
"$bin" bench transfer --config quickstart.toml --data-eval external.toml --seeds 2 \
    --variants base,no-fliplr,no-hsv "${tiny[@]}" --set data.synthetic=0 \
    --out runs/transfer --quiet --no-train >stdout/transfer_notrain.txt
"$bin" bench ablation --config cpu_protocol.toml --syn 0 --variants base,no_c2psa \
    "${tiny[@]}" --out runs/ablation --train-only --quiet >stdout/ablation.txt
echo "recorded under $PWD"
