#!/bin/sh
# The AP-producing trainings behind BENCHMARKS.md, run one after another on the shared
# 2-core dev box (about 1.2 h there, under load; finished steps are read back, not redone): the CPU-protocol sweep (configs/cpu_protocol.toml;
# 1 seed; 0/50/100/150/200 synthetic = the paper's 0/250/…/1000 per 60 real, scaled to 12
# real training images) and the scene ablation trainings (cpu_protocol + 50 synthetic,
# one model option changed per variant). Training is deterministic, so the AP numbers do
# not depend on machine load. Every step is resumable: rerun the script after a stop.
#
# Usage: bench/cpu_protocol_runs.sh [path/to/chicktrain]   (run from the repository root)
set -e
CT=${1:-chicktrain}
SWEEP=runs/sweep/cpu_protocol
ABL=runs/ablation/cpu_protocol
sweep() { "$CT" sweep --config configs/cpu_protocol.toml --seeds 1 --out $SWEEP --quiet --syn "$1"; }
sweep 0,50
# The ablation's base variant is exactly the sweep's 50-synthetic run.
mkdir -p $ABL
[ -e $ABL/base/test.json ] || { rm -rf $ABL/base; cp -r $SWEEP/syn50_seed0 $ABL/base; }
"$CT" bench ablation --out $ABL --train-only --quiet
sweep 0,50,100,200
# At 15 epochs the real-only run gets 2 steps per epoch (30 in all) and learns nothing; this
# row gives it the optimiser steps of the 50-synthetic run (78 epochs x 12 images).
"$CT" sweep --config configs/cpu_protocol.toml --seeds 1 --syn 0 --set train.epochs=78 \
  --out runs/sweep/cpu_protocol_real_78ep --quiet
sweep 0,50,100,150,200
# Copy the small report files that BENCHMARKS.md shows.
R=bench/results/sweep_cpu_protocol
mkdir -p $R
cp $SWEEP/sweep.md $SWEEP/sweep.csv $SWEEP/sweep.png $SWEEP/runs.csv $R/
cp runs/sweep/cpu_protocol_real_78ep/sweep.md $R/real_78ep.md
cp $SWEEP/syn200_seed0/plots.png $R/syn200_run_plots.png
