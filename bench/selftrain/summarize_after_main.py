#!/usr/bin/env python3
"""Tables of after_main.sh's results: per test half (Blender ids 61-120, Mitsuba ids
51-100) and checkpoint, zero-shot segm AP of the main job (700 steps), of 700 more steps
of renders alone (ctrl) and of 700 more steps with that set's unlabeled half, labelled by
the run's EMA model (xd / xd2) or once by the main job's best.bpk (fx / fx2), per seed,
with means ± sample std and the paired differences self-training minus ctrl; then the
pseudo-instances of each labelling, the detections on bench/negatives/ and the wall
time of each run. Missing files show as
"–". Standard library only:
    python3 bench/selftrain/summarize_after_main.py RESULTS SEED...
"""
import json
import os
import statistics
import sys

SETS = (("crossdomain", "xd", "fx", "Blender set, test half (ids 61-120)"),
        ("crossdomain2", "xd2", "fx2", "Mitsuba set, test half (ids 51-100)"))
ARMS = ("main", "ctrl", "xd", "xd2", "fx", "fx2")


def segm(path):
    """(segm AP, bbox AP) of an `eval --json` file, or None when it is missing."""
    if not os.path.exists(path):
        return None
    with open(path) as f:
        d = json.load(f)
    return d["segm"]["stats"][0], d["bbox"]["stats"][0]


def mean_sd(xs, signed=False):
    fmt = "{:+.3f}" if signed else "{:.3f}"
    if not xs:
        return "–"
    m = fmt.format(statistics.mean(xs))
    return m + (f" ± {statistics.stdev(xs):.3f}" if len(xs) > 1 else "")


def table(res, seeds, key, ema, fixed, title, ck):
    print(f"\n## {title}, {ck}.bpk\n")
    print("| seed | main job (700 steps) | + 700 steps, renders alone (ctrl) "
          "| + unlabeled, EMA teacher | paired | + unlabeled, fixed teacher | paired |")
    print("|---|---|---|---|---|---|---|")
    cols = {k: [] for k in ("main", "ctrl", "ema", "dema", "fix", "dfix")}
    for s in seeds:
        m, c, e, x = (segm(f"{res}/{a}_s{s}_{ck}_{key}.json")
                      for a in ("main", "ctrl", ema, fixed))
        cells = []
        for k, v in (("main", m), ("ctrl", c)):
            cells.append(f"{v[0]:.3f}" if v else "–")
            if v:
                cols[k].append(v[0])
        for k, d, v in (("ema", "dema", e), ("fix", "dfix", x)):
            cells.append(f"{v[0]:.3f}" if v else "–")
            if v:
                cols[k].append(v[0])
            if v and c:
                cols[d].append(v[0] - c[0])
                cells.append(f"{v[0] - c[0]:+.3f}")
            else:
                cells.append("–")
        print(f"| {s} | " + " | ".join(cells) + " |")
    print("| mean | " + " | ".join(mean_sd(cols[k], k.startswith("d")) for k in cols) + " |")


def labels(res, seeds):
    print("\n## Pseudo-instances per labelling (self_training.jsonl)\n")
    print("| run | before epoch | instances |")
    print("|---|---|---|")
    for s in seeds:
        for a in ("xd", "xd2", "fx", "fx2"):
            p = f"{res}/{a}_s{s}_self_training.jsonl"
            if not os.path.exists(p):
                continue
            recs = [r for r in (json.loads(l) for l in open(p) if l.strip())
                    if r.get("labelled")]
            eps = ", ".join(str(r.get("epoch", "?")) for r in recs)
            ins = ", ".join(str(r.get("instances", "?")) for r in recs)
            print(f"| {a}_s{s} | {eps} | {ins} |")


def per_arm(title, seeds, cell):
    """A table of one cell per seed and arm; cell(arm, seed) gives its text or None."""
    print(f"\n## {title}\n")
    print("| seed | " + " | ".join(ARMS) + " |")
    print("|---" * (len(ARMS) + 1) + "|")
    for s in seeds:
        print(f"| {s} | " + " | ".join(cell(a, s) or "–" for a in ARMS) + " |")


def read_if(path, parse):
    return parse(open(path)) if os.path.exists(path) else None


def negatives(res, seeds):
    """after_main.sh's negatives counts: detections above 0.25 / 0.5 over the ten photos."""
    per_arm("Detections on the ten carcass-free photos (best.bpk; > 0.25 / > 0.5)", seeds,
            lambda a, s: read_if(f"{res}/{a}_s{s}_negatives.txt", lambda f: " / ".join(
                l.split("total ")[1].split()[0] for l in f if "total " in l)))


def walls(res, seeds):
    per_arm("Wall time of each run (s; one thread, runs side by side, so a scale only)", seeds,
            lambda a, s: read_if(f"{res}/{a}_s{s}.wall_s", lambda f: f.read().strip()))


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: summarize_after_main.py RESULTS SEED...")
    res, seeds = sys.argv[1], sys.argv[2:]
    for key, ema, fixed, title in SETS:
        for ck in ("best", "last"):
            table(res, seeds, key, ema, fixed, title, ck)
    labels(res, seeds)
    negatives(res, seeds)
    walls(res, seeds)


if __name__ == "__main__":
    main()
