#!/bin/sh
# A/B of the vendored burn-flex patch (vendor/burn-flex/PATCH.md): two chicktrain binaries,
# one built without the patch (delete the `[patch.crates-io]` table of Cargo.toml, `cargo
# update -p burn-flex`, build) and one with it, timed in turns (ABAB…) so that the drift of a
# shared machine falls on both alike: bench/models_ab.sh at 256 px, sides labelled
# upstream / patched (batch-1 latency, 30 runs; training img/s at batch 8, 4 steps; fresh
# processes).
#
# Usage: bench/flex_patch_ab.sh UPSTREAM_BIN PATCHED_BIN [ROUNDS=6] [OUT=bench/results/speed/flex_patch_ab_256.csv]
LABELS="upstream patched" exec "$(dirname "$0")/models_ab.sh" "$1" "$2" "${3:-6}" 256 \
  "${4:-bench/results/speed/flex_patch_ab_256.csv}"
