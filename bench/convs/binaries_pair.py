"""The ratio table of bench/convs/binaries_pair.sh: OLD ÷ NEW per model, size and pass of
`bench convs` (each side the median of its two rounds, shapes weighted by their layer
count, the path flex dispatches), ONNX Runtime beside NEW where ort_convs.csv exists, and
`bench models` latency / training img/s. Prints markdown.

    python3 bench/convs/binaries_pair.py OUT
"""

import csv
import os
import statistics
import sys
from collections import defaultdict

from convs_csv import used_ms


def totals(path):
    """(model, size, pass) -> (ms summed over layers, GFLOP summed)."""
    t = defaultdict(lambda: [0.0, 0.0])
    with open(path) as f:
        for r in csv.DictReader(f):
            n = int(r["count"])
            k = (r["model"], int(r["size"]), r["pass"])
            t[k][0] += n * used_ms(r)
            t[k][1] += n * float(r["gflop"])
    return t


def peak_line(md_path):
    with open(md_path) as f:
        for line in f:
            if line.startswith("Peak: "):
                return line.strip()
    return "Peak: ?"


def peak_gflops(md_path):
    return float(peak_line(md_path).split("Peak: ")[1].split(" GFLOP/s")[0].split("= ")[-1])


def main() -> None:
    out = sys.argv[1]
    print("# Two binaries, one box (bench/convs/binaries_pair.sh)\n")
    with open(os.path.join(out, "machine.txt")) as f:
        print("```\n" + f.read().rstrip() + "\n```\n")
    for batch in ("b1", "b8"):
        sides = {}
        for side in ("old", "new"):
            runs = [totals(os.path.join(out, f"convs_{batch}_{side}_{r}", "convs.csv")) for r in (1, 2)]
            sides[side] = {k: (statistics.median([run[k][0] for run in runs]), runs[0][k][1]) for k in runs[0]}
        md_new = os.path.join(out, f"convs_{batch}_new_1", "convs.md")
        pk = peak_gflops(md_new)
        ort = {}
        ort_csv = os.path.join(out, f"convs_{batch}_new_1", "ort_convs.csv")
        if os.path.exists(ort_csv):
            with open(ort_csv) as f:
                for r in csv.DictReader(f):
                    k = (r["model"], int(r["size"]), "forward")
                    ort[k] = ort.get(k, 0.0) + int(r["count"]) * float(r["ort_node_ms"])
        print(f"## `bench convs`, batch {batch[1:]}\n")
        print(f"NEW's {peak_line(md_new)}\n")
        print("| model | size | pass | OLD ms | NEW ms | OLD ÷ NEW | NEW GFLOP/s | NEW % of peak | ONNX Runtime node ms | NEW ÷ ONNX Runtime |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for k in sides["new"]:
            o, n = sides["old"][k][0], sides["new"][k][0]
            g = sides["new"][k][1]
            rate = g / n * 1e3
            orts = f"{ort[k]:.2f} | {n / ort[k]:.2f}" if k in ort else "– | –"
            print(f"| {k[0]} | {k[1]} | {k[2]} | {o:.2f} | {n:.2f} | {o / n:.2f} | {rate:.1f} | {100 * rate / pk:.1f} | {orts} |")
        print()
    rows = {}
    for side in ("old", "new"):
        p = os.path.join(out, f"models_{side}", "bench.csv")
        if not os.path.exists(p):
            continue
        with open(p) as f:
            for r in csv.DictReader(f):
                rows[(side, r["variant"], r["size"])] = r
    if rows:
        print("## `bench models --variants yolo-n` (batch-1 latency median, training img/s at batch 8)\n")
        print("| size | OLD latency ms | NEW latency ms | OLD ÷ NEW | OLD train img/s | NEW train img/s | NEW ÷ OLD |")
        print("|---|---|---|---|---|---|---|")
        for (side, v, s), r in sorted(rows.items(), key=lambda x: int(x[0][2])):
            if side != "new" or ("old", v, s) not in rows:
                continue
            o = rows[("old", v, s)]
            lo, ln = float(o["latency_ms_median"]), float(r["latency_ms_median"])
            to, tn = float(o["train_img_s"]), float(r["train_img_s"])
            print(f"| {s} | {lo:.1f} | {ln:.1f} | {lo / ln:.2f} | {to:.2f} | {tn:.2f} | {tn / to:.2f} |")


if __name__ == "__main__":
    main()
