#!/usr/bin/env python3
"""Times chicktrain's COCO evaluator against pycocotools and faster-coco-eval, side by side.

The case mirrors bench/results/peers-measured.md: 180 images (640x640), ~871 polygon GT
instances, ~1759 RLE detections with boxes. Each tool is timed on load + evaluate +
accumulate (summarize excluded), median of N runs, all on this machine in one run.

From the repository root (bench/requirements.txt pins pycocotools 2.0.11, faster-coco-eval 1.8.0):
  python3 -m venv .venv && .venv/bin/pip install -r bench/requirements.txt
  cargo build --release
  .venv/bin/python bench/coco_speed.py --bin target/release/chicktrain --repeats 11
"""
import argparse
import contextlib
import io
import json
import os
import statistics
import subprocess
import tempfile
import time

import numpy as np
from pycocotools import mask as M


def star(rng, cx, cy, r, n=40):
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.random() * 0.1
    rad = r * (0.75 + 0.25 * np.sin(ang * 3 + rng.random() * 6)) * (0.9 + 0.1 * rng.random(n))
    return [round(float(v), 2) for v in np.stack([cx + rad * np.cos(ang), cy + 0.7 * rad * np.sin(ang)], 1).reshape(-1)]


def make(seed=0, n_img=180, h=640, w=640):
    rng = np.random.default_rng(seed)
    images, anns, dets = [], [], []
    aid = 1
    for i in range(n_img):
        iid = i + 1
        images.append({"id": iid, "file_name": f"{iid:04d}.jpg", "height": h, "width": w})
        for _ in range(int(rng.integers(2, 8))):  # mean ~4.8 per image -> ~870
            poly = star(rng, rng.random() * w, rng.random() * h, 40 + 60 * rng.random())
            r = M.merge(M.frPyObjects([poly], h, w))
            anns.append({"id": aid, "image_id": iid, "category_id": 1, "segmentation": [poly],
                         "area": float(M.area(r)), "bbox": [float(v) for v in M.toBbox(r)], "iscrowd": 0})
            aid += 1
            for _ in range(2):  # two detections per GT (one good, one sloppy)
                m = M.decode(r)
                m = np.roll(np.roll(m, int(rng.normal(0, 4)), 0), int(rng.normal(0, 4)), 1)
                e = M.encode(np.asfortranarray(m))
                dets.append({"image_id": iid, "category_id": 1, "score": float(rng.random()),
                             "segmentation": {"size": [h, w], "counts": e["counts"].decode()},
                             "bbox": [float(v) for v in M.toBbox(e)]})
    return {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "carcass"}]}, dets


def time_py(mod_coco, mod_eval, gt, dt, t, repeats):
    times = []
    for _ in range(repeats):
        with contextlib.redirect_stdout(io.StringIO()):
            t0 = time.perf_counter()
            g = mod_coco(gt)
            d = g.loadRes(dt)
            e = mod_eval(g, d, t)
            e.evaluate()
            e.accumulate()
            times.append(time.perf_counter() - t0)
            e.summarize()
    return statistics.median(times), list(e.stats)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--repeats", type=int, default=11)
    a = ap.parse_args()
    gt, dets = make()
    print(f"case: {len(gt['images'])} images, {len(gt['annotations'])} GT, {len(dets)} RLE detections")
    from pycocotools.coco import COCO as PC
    from pycocotools.cocoeval import COCOeval as PE
    from faster_coco_eval import COCO as FC, COCOeval_faster as FE
    with tempfile.TemporaryDirectory() as tmp:
        g, d = os.path.join(tmp, "gt.json"), os.path.join(tmp, "dt.json")
        json.dump(gt, open(g, "w"))
        json.dump(dets, open(d, "w"))
        out = subprocess.run([a.bin, "bench", "coco", "--gt", g, "--dt", d, "--repeats", str(a.repeats)],
                             capture_output=True, text=True, check=True).stdout
        ours = {line.split(":")[0].lower(): float(line.split("median ")[1].split(" s")[0]) for line in out.splitlines()}
        ours_ap = {line.split(":")[0].lower(): line.split("(AP ")[1].rstrip(")") for line in out.splitlines()}
        print("| iou | pycocotools 2.0.11 | faster-coco-eval 1.8.0 | chicktrain | faster / chicktrain | AP (pycocotools / chicktrain) |")
        print("|---|---|---|---|---|---|")
        for t in ("bbox", "segm"):
            tp, sp = time_py(PC, PE, g, d, t, max(3, a.repeats // 3))
            tf, sf = time_py(FC, FE, g, d, t, a.repeats)
            print(f"| {t} | {tp:.4f} s | {tf:.4f} s | {ours[t]:.4f} s | {tf / ours[t]:.2f}x | {sp[0]:.4f} / {ours_ap[t]} |")
        print(out.strip())


if __name__ == "__main__":
    main()
