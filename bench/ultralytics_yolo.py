#!/usr/bin/env python3
"""Times ultralytics YOLO11n-seg on the CPU the way bench/results/peers-measured.md did,
to put chicktrain's `examples/yolo_bench` numbers side by side on the same machine.

From the repository root (bench/requirements.txt pins ultralytics 8.4.190, torch 2.15.0):
  python3 -m venv .venv && .venv/bin/pip install -r bench/requirements.txt
  .venv/bin/python bench/ultralytics_yolo.py 320 640
  cargo run --release --example yolo_bench -- n 320 640

Train step: SegmentationModel('yolo11n-seg.yaml', nc=1), default hyperparameters, SGD,
random 8x3xSxS batch with 6 boxes and masks per image, forward + loss + backward + step,
one warm-up then the median of 3. Inference: batch 1, eval mode, no_grad, median of 5.
"""
import statistics
import sys
import time

import torch
from ultralytics.cfg import get_cfg
from ultralytics.nn.tasks import SegmentationModel

torch.set_num_threads(2)


def batch(size, b=8, n=6):
    g = torch.Generator().manual_seed(0)
    imgs = torch.rand(b, 3, size, size, generator=g)
    boxes, idx, cls, masks = [], [], [], torch.zeros(b, size, size)
    for i in range(b):
        for k in range(n):
            cx, cy = torch.rand(2, generator=g) * 0.6 + 0.2
            w, h = torch.rand(2, generator=g) * 0.2 + 0.1
            boxes.append([cx, cy, w, h]); idx.append(i); cls.append(0)
            x0, x1 = int((cx - w / 2) * size), int((cx + w / 2) * size)
            y0, y1 = int((cy - h / 2) * size), int((cy + h / 2) * size)
            masks[i, y0:y1, x0:x1] = k + 1
    return {"img": imgs, "bboxes": torch.tensor(boxes), "batch_idx": torch.tensor(idx, dtype=torch.float),
            "cls": torch.tensor(cls, dtype=torch.float).view(-1, 1), "masks": masks}


def main():
    for size in map(int, sys.argv[1:] or ["320", "640"]):
        model = SegmentationModel("yolo11n-seg.yaml", nc=1, verbose=False)
        model.args = get_cfg()
        model.train()
        opt = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.937, nesterov=True)
        b = batch(size)
        times = []
        for step in range(4):
            t0 = time.perf_counter()
            loss, _ = model.loss(b)
            opt.zero_grad()
            loss.sum().backward()
            opt.step()
            if step:
                times.append(time.perf_counter() - t0)
        train = statistics.median(times) / 8
        model.eval()
        x = torch.rand(1, 3, size, size)
        inf = []
        with torch.no_grad():
            for i in range(6):
                t0 = time.perf_counter()
                model(x)
                if i:
                    inf.append(time.perf_counter() - t0)
        print(f"ultralytics {size} px: train {train * 1e3:.1f} ms/img (batch 8), inference {statistics.median(inf) * 1e3:.1f} ms/img (batch 1)")


if __name__ == "__main__":
    main()
