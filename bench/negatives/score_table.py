#!/usr/bin/env python3
"""Tabulates arms of bench/negatives/score.sh over seeds: segm AP on the home test split
and both cross-domain sets, and detections on the carcass-free photos, per seed and as
mean ± sample std, with each arm's paired difference from the first arm.

    python3 bench/negatives/score_table.py DIR ARM [ARM ...]

DIR holds, per arm and seed S, the files score.sh writes, renamed with an ARM_sS_ prefix:
ARM_sS_home_test.json, ARM_sS_crossdomain.json, ARM_sS_crossdomain2.json and
ARM_sS_negatives.txt. Seeds are whatever the folder holds; a paired difference uses the
seeds both arms have.
"""
import json
import os
import re
import statistics
import sys

SETS = [("home", "home_test"), ("Blender set", "crossdomain"), ("Mitsuba set", "crossdomain2")]


def read_arm(folder, arm):
    seeds = {}
    for name in sorted(os.listdir(folder)):
        m = re.fullmatch(re.escape(arm) + r"_s(\d+)_negatives\.txt", name)
        if not m:
            continue
        s = int(m.group(1))
        row = {}
        for label, stem in SETS:
            with open(os.path.join(folder, f"{arm}_s{s}_{stem}.json")) as f:
                row[label] = json.load(f)["segm"]["stats"][0]
        with open(os.path.join(folder, name)) as f:
            totals = [int(t) for t in re.findall(r"total (\d+)", f.read())]
        if len(totals) != 2:
            sys.exit(f"{name}: expected two 'total N' lines (conf 0.25 and 0.5)")
        row["dets > 0.25"], row["dets > 0.5"] = totals
        seeds[s] = row
    if not seeds:
        sys.exit(f"{folder}: no {arm}_sS_negatives.txt")
    return seeds


def mean_std(values):
    if len(values) == 1:
        return f"{values[0]:.3f}"
    return f"{statistics.mean(values):.3f} ± {statistics.stdev(values):.3f}"


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    folder, arms = sys.argv[1], sys.argv[2:]
    data = {arm: read_arm(folder, arm) for arm in arms}
    cols = [label for label, _ in SETS] + ["dets > 0.25", "dets > 0.5"]
    print("| arm | seeds | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 2) + "|")
    for arm in arms:
        seeds = data[arm]
        cells = []
        for c in cols:
            per = [seeds[s][c] for s in sorted(seeds)]
            if c.startswith("dets"):
                cells.append(" / ".join(str(v) for v in per) + f" (mean {statistics.mean(per):.0f})")
            else:
                cells.append(" / ".join(f"{v:.3f}" for v in per) + f" ({mean_std(per)})")
        print(f"| {arm} | {', '.join(map(str, sorted(seeds)))} | " + " | ".join(cells) + " |")
    base = data[arms[0]]
    for arm in arms[1:]:
        common = sorted(set(base) & set(data[arm]))
        cells = []
        for label, _ in SETS:
            d = [data[arm][s][label] - base[s][label] for s in common]
            cells.append(" / ".join(f"{v:+.3f}" for v in d) + f" ({mean_std(d)})")
        print(f"\n{arm} − {arms[0]}, paired over seeds {common}: "
              + "; ".join(f"{label} {c}" for (label, _), c in zip(SETS, cells)))


if __name__ == "__main__":
    main()
