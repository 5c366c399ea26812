"""Per size, the median over rounds of each side of a bench/models_ab.sh CSV and the
ratios (latency old ÷ new, training new ÷ old), as Markdown. The sides are the CSV's two
`binary` labels, old first (the order the script runs them).
Usage: python3 bench/models_ab.py models_ab.csv"""
import csv
import statistics
import sys

rows = list(csv.DictReader(open(sys.argv[1])))
cols = ["latency_ms_median", "train_img_s", "train_peak_MiB", "infer_peak_MiB"]
print("| size | rounds | latency ms old / new | old ÷ new | train img/s old / new | new ÷ old "
      "| train peak MiB old / new | infer peak MiB old / new |")
print("|---|---|---|---|---|---|---|---|")
sides = list(dict.fromkeys(r["binary"] for r in rows))
for size in sorted({int(r["size"]) for r in rows}):
    med = {}
    for side in sides:
        sel = [r for r in rows if r["binary"] == side and int(r["size"]) == size]
        med[side] = {c: statistics.median(float(r[c]) for r in sel) for c in cols}
        med[side]["n"] = len(sel)
    o, n = (med[side] for side in sides)
    print(f"| {size} | {o['n']} | {o['latency_ms_median']:.1f} / {n['latency_ms_median']:.1f} "
          f"| {o['latency_ms_median'] / n['latency_ms_median']:.2f} "
          f"| {o['train_img_s']:.2f} / {n['train_img_s']:.2f} | {n['train_img_s'] / o['train_img_s']:.2f} "
          f"| {o['train_peak_MiB']:.0f} / {n['train_peak_MiB']:.0f} "
          f"| {o['infer_peak_MiB']:.0f} / {n['infer_peak_MiB']:.0f} |")
