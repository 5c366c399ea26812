"""How far predicted boxes and masks reach, against the cross-domain set's annotations.

Why: on the Blender set Mask R-CNN's segm AP is far above its bbox AP (0.415 vs 0.296),
while YOLO's is below (0.416 vs 0.481). This script tells loose boxes from short ones
and both from a bad evaluator: it scores `chicktrain predict`'s COCO results with
pycocotools (bbox, segm, and bbox recomputed from each predicted mask), then, for every
detection scoring > 0.5 whose mask overlaps a ground-truth mask at IoU >= 0.5, compares
its box, and the tight box of its mask, with that ground truth's box (width and height
ratios, centre offset as a fraction of the ground truth's size), and how well each
detection's mask fills its own box (IoU of the box with the mask's tight box).

    chicktrain predict --checkpoint runs/X/best.bpk --input bench/crossdomain/set/images \
        --out runs/X/pred --conf 0.05
    python bench/crossdomain/box_extent.py runs/X/pred [more prediction folders]

`ANN=path/annotations.json` scores against another COCO file instead (e.g. the proxy-real
renders of `chicktrain render --preset proxy-real`, to compare with the home domain).
Needs numpy and pycocotools (bench/crossdomain/requirements.txt).
"""

import contextlib
import io
import json
import os
import sys

import numpy as np
from pycocotools import mask as mask_util
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

HERE = os.path.dirname(os.path.abspath(__file__))
ANNOTATIONS = os.environ.get("ANN", os.path.join(HERE, "set", "annotations.json"))


def coco_stats(gt, results, iou_type):
    with contextlib.redirect_stdout(io.StringIO()):
        e = COCOeval(gt, gt.loadRes(results), iou_type)
        e.evaluate()
        e.accumulate()
        e.summarize()
    return e.stats


def load_results(gt, folder):
    """`predict`'s results.json with image ids mapped to the annotations' by file name."""
    by_name = {os.path.basename(im["file_name"]): im["id"] for im in gt.dataset["images"]}
    with open(os.path.join(folder, "images.json")) as f:
        images = json.load(f)["images"]
    to_gt = {im["id"]: by_name[os.path.basename(im["file_name"])] for im in images}
    with open(os.path.join(folder, "results.json")) as f:
        results = json.load(f)
    for r in results:
        r["image_id"] = to_gt[r["image_id"]]
    return results


MIN_SCORE = 0.5
MIN_IOU = 0.5


def matches(gt, results):
    """(detection index, ground-truth annotation) for every detection scoring > MIN_SCORE
    whose mask overlaps its best ground-truth mask at IoU >= MIN_IOU."""
    by_image = {}
    for k, r in enumerate(results):
        if r["score"] > MIN_SCORE:
            by_image.setdefault(r["image_id"], []).append(k)
    out = []
    for image_id, dets in by_image.items():
        anns = gt.loadAnns(gt.getAnnIds(imgIds=image_id))
        if not anns:
            continue
        rles = [gt.annToRLE(a) for a in anns]
        iou = mask_util.iou([results[k]["segmentation"] for k in dets], rles, [0] * len(rles))
        for i, k in enumerate(dets):
            j = int(np.argmax(iou[i]))
            if iou[i, j] >= MIN_IOU:
                out.append((k, anns[j]))
    return out


def box_extent(pairs, boxes):
    """Width / height ratios and centre offsets (fractions of the GT's size) of `boxes`
    (xywh, indexed like the results) against the matched ground truths' boxes."""
    ratios, offsets = [], []
    for k, ann in pairs:
        g, p = ann["bbox"], boxes[k]
        ratios.append((p[2] / g[2], p[3] / g[3]))
        offsets.append((
            abs(p[0] + p[2] / 2 - g[0] - g[2] / 2) / g[2],
            abs(p[1] + p[3] / 2 - g[1] - g[3] / 2) / g[3],
        ))
    return np.array(ratios), np.array(offsets)


def main(folders):
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(ANNOTATIONS)
    # The annotations' boxes are the tight boxes of their masks (checked, not assumed).
    worst = max(
        float(np.abs(np.array(a["bbox"]) - mask_util.toBbox(gt.annToRLE(a))).max())
        for a in gt.dataset["annotations"]
    )
    print(f"annotation boxes vs their masks' tight boxes: largest difference {worst:.2f} px")
    print("| predictions | bbox AP / AP75 | segm AP / AP75 | bbox from mask AP / AP75 "
          "| matched | box width ratio (median, IQR) | box height ratio | box centre offset x / y "
          "| mask width / height ratio (median; 90th pct of width) | box vs own mask's box IoU (median) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for folder in folders:
        results = load_results(gt, folder)
        b = coco_stats(gt, results, "bbox")
        s = coco_stats(gt, results, "segm")
        from_mask = [dict(r, bbox=mask_util.toBbox(r["segmentation"]).tolist()) for r in results]
        m = coco_stats(gt, from_mask, "bbox")
        # One matching (by mask) for both box sets: the masks are the same either way.
        pairs = matches(gt, results)
        ratios, offsets = box_extent(pairs, [r["bbox"] for r in results])
        mask_ratios, _ = box_extent(pairs, [f["bbox"] for f in from_mask])
        q = np.percentile(ratios, [25, 50, 75], axis=0)
        off = np.median(offsets, axis=0)
        mq = np.median(mask_ratios, axis=0)
        m90 = np.percentile(mask_ratios[:, 0], 90)
        fill = np.median([
            mask_util.iou([r["bbox"]], [f["bbox"]], [0])[0][0]
            for r, f in zip(results, from_mask) if r["score"] > MIN_SCORE
        ])
        print(f"| {folder} | {b[0]:.3f} / {b[2]:.3f} | {s[0]:.3f} / {s[2]:.3f} "
              f"| {m[0]:.3f} / {m[2]:.3f} | {len(ratios)} "
              f"| {q[1, 0]:.3f} ({q[0, 0]:.3f}–{q[2, 0]:.3f}) | {q[1, 1]:.3f} "
              f"| {off[0]:.3f} / {off[1]:.3f} | {mq[0]:.3f} / {mq[1]:.3f}; {m90:.3f} | {fill:.3f} |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
