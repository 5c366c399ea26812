#!/usr/bin/env python3
"""Table of run.sh's results: zero-shot segm / bbox AP on the test half per seed and
arm, best.bpk and last.bpk, and the paired difference (self-training minus base).
Standard library only:  python3 bench/crossdomain/selftrain/summarize.py RESULTS SEED...
"""
import json
import statistics
import sys


def stats(path):
    with open(path) as f:
        d = json.load(f)
    return d["segm"]["stats"][0], d["bbox"]["stats"][0], d["segm"]["stats"][1]


def main():
    res, seeds = sys.argv[1], sys.argv[2:]
    print("| seed | checkpoint | base segm AP | self-training segm AP | diff | base bbox AP | self-training bbox AP | base segm AP50 | self-training segm AP50 |")
    print("|---|---|---|---|---|---|---|---|---|")
    diffs = {"best": [], "last": []}
    for s in seeds:
        for ck in ("best", "last"):
            b = stats(f"{res}/base_s{s}_{ck}.json")
            t = stats(f"{res}/selftrain_s{s}_{ck}.json")
            diffs[ck].append(t[0] - b[0])
            print(f"| {s} | {ck} | {b[0]:.3f} | {t[0]:.3f} | {t[0] - b[0]:+.3f} | {b[1]:.3f} | {t[1]:.3f} | {b[2]:.3f} | {t[2]:.3f} |")
    for ck, d in diffs.items():
        sd = f" ± {statistics.stdev(d):.3f}" if len(d) > 1 else ""
        print(f"\nsegm AP difference ({ck}.bpk), mean over {len(d)} seed(s): {statistics.mean(d):+.3f}{sd}")


if __name__ == "__main__":
    main()
