#!/usr/bin/env python3
"""Tabulates a `bench/quickstart_pair.sh` folder: per-epoch seconds and val AP of both
sides (`OUT/{old,new}/results.csv`), their totals and ratio, wall times (`OUT/wall.txt`),
the load (`OUT/load_start.txt`, `OUT/load_samples.txt`) and the test AP of each side's
best checkpoint (`OUT/{old,new}/test.json`), as Markdown on stdout.

    python3 bench/quickstart_pair_table.py OUT
"""
import csv
import json
import sys
from pathlib import Path


def epochs(side: Path):
    with open(side / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def load_averages(out: Path):
    """The 1-minute load averages of every sample."""
    values = []
    for name in ("load_start.txt", "load_samples.txt"):
        path = out / name
        if not path.exists():
            continue
        for line in path.read_text().splitlines():
            if "load average:" in line:
                values.append(float(line.split("load average:")[1].split(",")[0]))
    return values


def test_ap(side: Path):
    path = side / "test.json"
    if not path.exists():
        return None
    report = json.loads(path.read_text())
    return report["bbox"]["stats"][0], report["segm"]["stats"][0], report.get("epoch")


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(sys.argv[1])
    old, new = epochs(out / "old"), epochs(out / "new")
    print("| epoch | old s | new s | old ÷ new | old val segm AP | new val segm AP |")
    print("|---|---|---|---|---|---|")
    for i in range(max(len(old), len(new))):
        row = [str(i + 1)]
        o = old[i] if i < len(old) else None
        n = new[i] if i < len(new) else None
        row += [f"{float(r['time']):.1f}" if r else "—" for r in (o, n)]
        row.append(f"{float(o['time']) / float(n['time']):.2f}" if o and n else "—")
        row += [f"{float(r['val/segm_AP']):.3f}" if r else "—" for r in (o, n)]
        print("| " + " | ".join(row) + " |")
    common = min(len(old), len(new))
    t_old = sum(float(r["time"]) for r in old[:common])
    t_new = sum(float(r["time"]) for r in new[:common])
    print()
    print(f"Epochs 1–{common}, summed epoch times: old {t_old:.1f} s, new {t_new:.1f} s, "
          f"old ÷ new {t_old / t_new:.3f}.")
    wall = out / "wall.txt"
    if wall.exists():
        print(f"Wall times (`wall.txt`, data preparation included): "
              f"{'; '.join(wall.read_text().split(chr(10))).strip('; ')}.")
    loads = load_averages(out)
    if loads:
        print(f"Load average (1 min) over {len(loads)} samples: min {min(loads):.1f}, "
              f"median {sorted(loads)[len(loads) // 2]:.1f}, max {max(loads):.1f}.")
    for name in ("old", "new"):
        ap = test_ap(out / name)
        if ap:
            print(f"Test ({name}, best checkpoint of epoch {ap[2]}): bbox AP {ap[0]:.3f}, "
                  f"segm AP {ap[1]:.3f}.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
