#!/bin/bash
# Wall time of `chicktrain eval` with two binaries, interleaved, best of N runs each (the
# minimum is the least disturbed by other load on a shared machine), on the sets of
# BENCHMARKS.md "Masks at the original size". Run from the repository root:
#   bench/retina/eval_ab.sh OLD_BINARY NEW_BINARY CHECKPOINT [N]
# e.g. OLD_BINARY built from the commit before retina masks, NEW_BINARY target/release/chicktrain.
set -euo pipefail
declare -A best
old=$1 new=$2 ck=$3 n=${4:-5}
sets=("--split test" "--data bench/retina/proxy640.toml --split test" "--data bench/crossdomain/crossdomain.toml --split test")
for s in "${sets[@]}"; do
  $new eval --checkpoint "$ck" $s > /dev/null # render / warm the caches once
  for b in old new; do best[$b]=1000000; done
  for i in $(seq "$n"); do
    for b in old new; do
      bin=${!b}
      t0=$(date +%s.%N)
      $bin eval --checkpoint "$ck" $s > /dev/null
      best[$b]=$(awk -v a="$(date +%s.%N)" -v b="$t0" -v m="${best[$b]}" 'BEGIN { t = a - b; print (t < m ? t : m) }')
    done
  done
  printf '%s: old %.2f s, new %.2f s (best of %d)\n' "$s" "${best[old]}" "${best[new]}" "$n"
done
