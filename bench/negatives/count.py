#!/usr/bin/env python3
"""Detections per carcass-free photo from `chicktrain predict`'s images.json files.

    python3 bench/negatives/count.py pred_0.25/images.json pred_0.5/images.json

Prints one line per file: the threshold's folder name, the total and the count per
image (in the order of bench/negatives/README.md's table). Standard library only.
"""

import json
import os
import sys

ORDER = ["astronaut", "coffee", "chelsea", "rocket", "camera", "coins", "clock", "brick", "gravel", "grass"]


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for path in sys.argv[1:]:
        with open(path) as fh:
            images = json.load(fh)["images"]
        per = {os.path.splitext(os.path.basename(i["file_name"]))[0]: i["detections"] for i in images}
        missing = [n for n in ORDER if n not in per]
        if missing:
            sys.exit(f"{path}: no entry for {', '.join(missing)}")
        label = os.path.basename(os.path.dirname(os.path.abspath(path)))
        counts = " ".join(f"{n}={per[n]}" for n in ORDER)
        print(f"{label}: total {sum(per.values())} per-image {sum(per.values()) / len(per):.1f} | {counts}")


if __name__ == "__main__":
    main()
