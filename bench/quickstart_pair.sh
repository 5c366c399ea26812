#!/bin/bash
# The quickstart trained by two binaries at the same time (same box state), each at one
# rayon thread and nice 5, same config, separate run folders and render caches; issue 37's
# before/after. Per-epoch times and val AP land in OUT/{old,new}/results.csv, wall times in
# OUT/wall.txt, the load every 60 s in OUT/load_samples.txt. Pinned at 25 epochs (350 steps)
# without negative renders, as every pair so far was measured (the quickstart itself trains
# 50 epochs with them since 2026-12-05).
#   bench/quickstart_pair.sh OLD_BINARY NEW_BINARY OUT
set -u
if [ $# -ne 3 ]; then echo "usage: $0 OLD_BINARY NEW_BINARY OUT" >&2; exit 2; fi
OLD=$(realpath "$1"); NEW=$(realpath "$2"); mkdir -p "$3"; OUT=$(realpath "$3")
cd "$(dirname "$0")/.."
uptime > "$OUT/load_start.txt"; date -u >> "$OUT/load_start.txt"
for side in old new; do
  BIN=$OLD; [ $side = new ] && BIN=$NEW
  ( start=$(date +%s)
    RAYON_NUM_THREADS=1 nice -n 5 "$BIN" --config configs/quickstart.toml \
      --run-dir "$OUT/$side" --set train.epochs=25 \
      --set data.negatives.empty=0 --set data.negatives.distractors=0 --set data.cache="$OUT/cache_$side" > "$OUT/$side.log" 2> "$OUT/$side.err"
    rc=$?
    echo "$side rc=$rc wall_s=$(( $(date +%s) - start ))" >> "$OUT/wall.txt"
  ) &
done
( while pgrep -f "run-dir $OUT/" >/dev/null; do uptime >> "$OUT/load_samples.txt"; sleep 60; done ) &
wait
