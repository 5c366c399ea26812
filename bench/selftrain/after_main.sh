#!/usr/bin/env bash
# Self-training after the main job (issue 38 part 3, BENCHMARKS.md "Transfer"). For each
# seed S:
#   main_sS  the main job, configs/quickstart.toml (700 steps; reused if OUT/main_sS has
#            best.bpk, e.g. a link to an earlier run of the same seed),
#   ctrl_sS  700 more steps of the same recipe from main_sS/best.bpk (model.init),
#   xd_sS    the same plus the Blender set's unlabeled half
#            (bench/crossdomain/selftrain/after_main.toml),
#   xd2_sS   the same plus the Mitsuba set's unlabeled half
#            (bench/crossdomain2/selftrain/after_main.toml),
#   fx_sS / fx2_sS  as xd / xd2, but main_sS/best.bpk labels once, fixed
#            (train.self_training.teacher), keeping fused instances scoring >= 0.25,
# so ctrl and the self-training arms differ only in the unlabeled photos, at equal
# optimiser steps. ARMS="ctrl xd xd2 fx fx2" (the default) picks the second-stage arms.
# Each is scored zero-shot without TTA on the test halves (ids 61-120 of the Blender set,
# 51-100 of the Mitsuba set; labels of the unlabeled halves are never read), best.bpk
# and last.bpk, and each best.bpk on the ten carcass-free photos of bench/negatives/
# (bench/negatives/detections.sh). The second-stage runs go JOBS at a time (default 2) at one thread each;
# training is deterministic, so the load changes the times, not the metrics. CACHE=DIR
# shares a render cache between runs. Writes RESULTS/<arm>_s<S>_<ckpt>_<set>.json
# (eval --json), RESULTS/<arm>_s<S>_negatives.txt (detections above 0.25 and 0.5), each
# run's metrics.jsonl / self_training.jsonl / wall time, and
# RESULTS/summary.md.
#
#   bench/selftrain/after_main.sh target/release/chicktrain runs/after_main \
#     bench/results/selftrain/after_main 0 1 2
set -euo pipefail
if [ $# -lt 4 ]; then
  echo "usage: $0 CHICKTRAIN OUT RESULTS SEED..." >&2
  exit 2
fi
BIN=$(realpath "$1") OUT=$2 RESULTS=$3
shift 3
mkdir -p "$OUT" "$RESULTS"
for set in crossdomain crossdomain2; do
  [ -n "$(ls bench/$set/selftrain/unlabeled 2>/dev/null)" ] || {
    echo "bench/$set/selftrain/unlabeled is empty: run bench/crossdomain/selftrain/make_split.py first" >&2
    exit 2
  }
done
extra=()
[ -n "${CACHE:-}" ] && extra=(--set "data.cache=$CACHE")

train() { # RUN CONFIG SEED [--set ...]
  local run=$1 cfg=$2 seed=$3
  shift 3
  [ -f "$run/test.json" ] && return 0
  local t0; t0=$(date +%s)
  RAYON_NUM_THREADS=${THREADS:-1} "$BIN" --config "$cfg" --run-dir "$run" --quiet \
    --set "seed=$seed" "${extra[@]}" "$@" > "$run.log" 2>&1
  echo "$(( $(date +%s) - t0 ))" > "$run.wall_s"
}

for S in "$@"; do
  [ -f "$OUT/main_s$S/best.bpk" ] || THREADS=${THREADS:-2} train "$OUT/main_s$S" configs/quickstart.toml "$S"
done

jobs=()
for S in "$@"; do
  for arm in ${ARMS:-ctrl xd xd2 fx fx2}; do
    case $arm in
      ctrl) jobs+=("ctrl_s$S configs/quickstart.toml $S") ;;
      xd|fx) jobs+=("${arm}_s$S bench/crossdomain/selftrain/after_main.toml $S") ;;
      xd2|fx2) jobs+=("${arm}_s$S bench/crossdomain2/selftrain/after_main.toml $S") ;;
      *) echo "unknown arm $arm (ctrl xd xd2 fx fx2)" >&2; exit 2 ;;
    esac
  done
done
running=0
for j in "${jobs[@]}"; do
  read -r name cfg S <<< "$j"
  fixed=()
  case $name in fx*) fixed=(--set "train.self_training.teacher=$OUT/main_s$S/best.bpk"
                             --set "train.self_training.score_threshold=0.25") ;; esac
  train "$OUT/$name" "$cfg" "$S" --set "model.init=$OUT/main_s$S/best.bpk" "${fixed[@]}" &
  running=$((running + 1))
  if [ "$running" -ge "${JOBS:-2}" ]; then wait -n; running=$((running - 1)); fi
done
wait

score() { # ARM SEED SET
  local run=$OUT/${1}_s$2
  [ -f "$run/best.bpk" ] || return 0
  for ck in best last; do
    local out=$RESULTS/${1}_s${2}_${ck}_$3.json
    [ -f "$out" ] || RAYON_NUM_THREADS=2 "$BIN" eval --checkpoint "$run/$ck.bpk" \
      --data "bench/$3/selftrain/test.toml" --split test --json > "$out"
  done
}
for S in "$@"; do
  for arm in main ctrl; do score $arm "$S" crossdomain; score $arm "$S" crossdomain2; done
  for arm in xd fx; do score $arm "$S" crossdomain; done
  for arm in xd2 fx2; do score $arm "$S" crossdomain2; done
  for arm in main ctrl xd xd2 fx fx2; do
    run=$OUT/${arm}_s$S
    [ -f "$run/metrics.jsonl" ] || continue
    neg=$RESULTS/${arm}_s${S}_negatives.txt
    if [ ! -f "$neg" ]; then
      RAYON_NUM_THREADS=2 bench/negatives/detections.sh "$BIN" "$run/best.bpk" "$run/negatives"
      cp "$run/negatives/negatives.txt" "$neg"
    fi
    cp "$run/metrics.jsonl" "$RESULTS/${arm}_s${S}_metrics.jsonl"
    [ -f "$run.wall_s" ] && cp "$run.wall_s" "$RESULTS/${arm}_s${S}.wall_s"
    [ -f "$run/self_training.jsonl" ] && cp "$run/self_training.jsonl" "$RESULTS/${arm}_s${S}_self_training.jsonl"
  done
done
python3 bench/selftrain/summarize_after_main.py "$RESULTS" "$@" | tee "$RESULTS/summary.md"
