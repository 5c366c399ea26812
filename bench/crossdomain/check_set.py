#!/usr/bin/env python3
"""Verify a cross-domain set and draw mask overlays.

    python check_set.py DIR [--overlay OUTDIR] [--ids 1,2,3]

Checks that DIR/annotations.json loads with pycocotools, that every image file exists
with the recorded size, that every RLE decodes to its image's size with the recorded
area and bbox, and that GT-as-detections gives segm and bbox AP = 1.0 under COCOeval.
With --overlay, writes side-by-side PNGs (image | image with coloured masks and
outlines) for the given image ids (default: the first 3).
"""

import argparse
import contextlib
import io
import os
import sys

import numpy as np
from PIL import Image
from pycocotools import mask as mask_util
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval


def overlay(coco, root, img_id, out_path):
    info = coco.loadImgs(img_id)[0]
    im = np.asarray(Image.open(os.path.join(root, "images", info["file_name"])).convert("RGB"))
    ov = im.astype(np.float32).copy()
    rng = np.random.default_rng(img_id)
    for a in coco.loadAnns(coco.getAnnIds(imgIds=img_id)):
        m = mask_util.decode(a["segmentation"]).astype(bool)
        col = rng.uniform(40, 255, 3)
        ov[m] = 0.5 * ov[m] + 0.5 * col
        edge = m & ~(np.roll(m, 1, 0) & np.roll(m, -1, 0) & np.roll(m, 1, 1) & np.roll(m, -1, 1))
        ov[edge] = (255, 255, 255)
    both = np.concatenate([im, ov.clip(0, 255).astype(np.uint8)], axis=1)
    big = Image.fromarray(both).resize((both.shape[1] * 2, both.shape[0] * 2), Image.NEAREST)
    big.save(out_path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root")
    ap.add_argument("--overlay")
    ap.add_argument("--ids", default="")
    args = ap.parse_args()
    path = os.path.join(args.root, "annotations.json")
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(path)
    imgs = coco.loadImgs(coco.getImgIds())
    anns = coco.loadAnns(coco.getAnnIds())
    bad = 0
    for info in imgs:
        p = os.path.join(args.root, "images", info["file_name"])
        with Image.open(p) as im:
            if im.size != (info["width"], info["height"]) or im.format != "JPEG":
                print("bad image", p, im.size, im.format)
                bad += 1
    for a in anns:
        info = coco.imgs[a["image_id"]]
        rle = a["segmentation"]
        m = mask_util.decode(rle)
        ok = (m.shape == (info["height"], info["width"]) and isinstance(rle["counts"], str)
              and int(m.sum()) == int(a["area"]) >= 100
              and np.allclose(mask_util.toBbox(rle), a["bbox"])
              and a["iscrowd"] == 0 and a["category_id"] == 1)
        if not ok:
            print("bad annotation", a["id"])
            bad += 1
    stats = {}
    for iou in ("segm", "bbox"):
        dets = [dict(image_id=a["image_id"], category_id=1, score=1.0,
                     segmentation=a["segmentation"], bbox=a["bbox"]) for a in anns]
        with contextlib.redirect_stdout(io.StringIO()):
            dt = coco.loadRes(dets)
            ev = COCOeval(coco, dt, iou)
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        stats[iou] = ev.stats
    per_img = np.bincount([a["image_id"] for a in anns], minlength=len(imgs) + 1)[1:]
    areas = np.array([a["area"] for a in anns])
    print(f"{len(imgs)} images, {len(anns)} instances "
          f"(per image min {per_img.min()}, mean {per_img.mean():.2f}, max {per_img.max()}); "
          f"area px median {np.median(areas):.0f} (min {areas.min():.0f}, max {areas.max():.0f})")
    print(f"GT-as-detections: segm AP {stats['segm'][0]:.3f} AP50 {stats['segm'][1]:.3f}; "
          f"bbox AP {stats['bbox'][0]:.3f}")
    if args.overlay:
        os.makedirs(args.overlay, exist_ok=True)
        ids = [int(x) for x in args.ids.split(",") if x] or [i["id"] for i in imgs[:3]]
        for i in ids:
            overlay(coco, args.root, i, os.path.join(args.overlay, f"overlay_{i:05d}.png"))
    ok = bad == 0 and abs(stats["segm"][0] - 1.0) < 1e-9 and abs(stats["bbox"][0] - 1.0) < 1e-9
    print("OK" if ok else f"FAILED ({bad} bad entries)")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
