#!/usr/bin/env bash
# Self-training at equal optimiser steps on the Blender cross-domain set (issue 38 part 3,
# BENCHMARKS.md "Transfer"): for each seed, the main job (configs/quickstart.toml, 350
# steps) alone against the same plus self-training on the set's unlabeled half
# (selftrain.toml: ids 1-60, labels never read), both scored zero-shot on the test half
# (test.toml: ids 61-120) without test-time augmentation, best.bpk (picked on the
# quickstart's proxy-real val split, as always) and last.bpk. The two runs of a seed go
# side by side at one thread each (training is deterministic: the load changes the time,
# not the metrics). Writes RESULTS/{base,selftrain}_s{S}_{best,last}.json (eval --json)
# and each run's metrics.jsonl, test.json and self_training.jsonl beside them.
#
#   bench/crossdomain/selftrain/run.sh target/release/chicktrain runs/selftrain bench/results/selftrain 0 1 2
set -euo pipefail
if [ $# -lt 4 ]; then
  echo "usage: $0 CHICKTRAIN OUT RESULTS SEED..." >&2
  exit 2
fi
BIN=$1 OUT=$2 RESULTS=$3
shift 3
mkdir -p "$OUT" "$RESULTS"
[ -e bench/crossdomain/selftrain/unlabeled/xd_00000.jpg ] || {
  echo "bench/crossdomain/selftrain/unlabeled is empty: run make_split.py first" >&2
  exit 2
}
pids=()
for S in "$@"; do
  for arm in base selftrain; do
    cfg=configs/quickstart.toml
    [ "$arm" = selftrain ] && cfg=bench/crossdomain/selftrain/selftrain.toml
    run="$OUT/${arm}_s$S"
    if [ ! -f "$run/test.json" ]; then
      RAYON_NUM_THREADS=1 "$BIN" --config "$cfg" --run-dir "$run" --set "seed=$S" \
        > "$OUT/${arm}_s$S.log" 2>&1 &
      pids+=($!)
    fi
  done
done
for p in "${pids[@]}"; do wait "$p"; done
for S in "$@"; do
  for arm in base selftrain; do
    run="$OUT/${arm}_s$S"
    for ck in best last; do
      RAYON_NUM_THREADS=1 "$BIN" eval --checkpoint "$run/$ck.bpk" \
        --data bench/crossdomain/selftrain/test.toml --split test --json \
        > "$RESULTS/${arm}_s${S}_$ck.json"
    done
    cp "$run/metrics.jsonl" "$RESULTS/${arm}_s${S}_metrics.jsonl"
    cp "$run/test.json" "$RESULTS/${arm}_s${S}_home_test.json"
    [ -f "$run/self_training.jsonl" ] && cp "$run/self_training.jsonl" "$RESULTS/${arm}_s${S}_self_training.jsonl"
  done
done
python3 bench/crossdomain/selftrain/summarize.py "$RESULTS" "$@" | tee "$RESULTS/summary.md"
