#!/usr/bin/env python3
"""Times ultralytics YOLO11n-seg on the CPU the way `chicktrain bench models` times
chicktrain's `yolo-n`, so the two sit side by side from one run on one machine.

From the repository root (bench/requirements.txt pins ultralytics 8.4.190, torch 2.15.0):
  python3 -m venv .venv && .venv/bin/pip install -r bench/requirements.txt
  .venv/bin/python bench/ultralytics_yolo.py 256 320 640 [--onnx-dir runs/speed]

Train step: SegmentationModel('yolo11n-seg.yaml', nc=1), default hyperparameters, SGD,
random 8x3xSxS batch with 6 boxes and masks per image, forward + loss + backward + step,
one warm-up then the median of --train-steps (default 5). Inference: batch 1, eval mode,
no_grad, one warm-up then the median of --repeats (default 10).

Each measurement runs in a fresh child process, as chicktrain's does, so the peak
resident memory it reports (the child's ru_maxrss, from wait4) belongs to that
measurement alone: the interpreter, torch and the model included, as in chicktrain's
column, which counts the whole process too.

--onnx-dir DIR also writes ultralytics' own ONNX export at each size
(`YOLO("yolo11n-seg.yaml").export(format="onnx", imgsz=S)`, its defaults otherwise) to
DIR/ultralytics_S.onnx, for bench/onnx_latency.py.
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time

THREADS = 2


def batch(torch, size, b=8, n=6):
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


def child(mode, size, steps):
    """One measurement, in this (fresh) process; prints one JSON line."""
    import torch
    from ultralytics.cfg import get_cfg
    from ultralytics.nn.tasks import SegmentationModel

    torch.set_num_threads(THREADS)
    model = SegmentationModel("yolo11n-seg.yaml", nc=1, verbose=False)
    times = []
    if mode == "train":
        model.args = get_cfg()
        model.train()
        opt = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.937, nesterov=True)
        b = batch(torch, size)
        for step in range(1 + steps):
            t0 = time.perf_counter()
            loss, _ = model.loss(b)
            opt.zero_grad()
            loss.sum().backward()
            opt.step()
            if step:
                times.append((time.perf_counter() - t0) / 8)
    else:
        model.eval()
        x = torch.rand(1, 3, size, size)
        with torch.no_grad():
            for i in range(1 + steps):
                t0 = time.perf_counter()
                model(x)
                if i:
                    times.append(time.perf_counter() - t0)
    print(json.dumps({"ms": statistics.median(times) * 1e3, "min": min(times) * 1e3, "max": max(times) * 1e3}))


def export(size, out_dir):
    from ultralytics import YOLO

    path = YOLO("yolo11n-seg.yaml").export(format="onnx", imgsz=size)
    os.makedirs(out_dir, exist_ok=True)
    shutil.move(path, os.path.join(out_dir, f"ultralytics_{size}.onnx"))


def run_child(args):
    p = subprocess.Popen([sys.executable, __file__, "--child", *args], stdout=subprocess.PIPE, text=True)
    out = p.stdout.read()
    _, status, ru = os.wait4(p.pid, 0)
    if status != 0:
        raise SystemExit(f"child {args} failed with status {status}")
    line = [l for l in out.splitlines() if l.startswith("{")][-1]
    r = json.loads(line)
    r["peak_rss_mib"] = ru.ru_maxrss / 1024  # KiB on Linux
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sizes", nargs="*", type=int, default=[320, 640])
    ap.add_argument("--train-steps", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--onnx-dir")
    ap.add_argument("--child", nargs=3, metavar=("MODE", "SIZE", "STEPS"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        mode, size, steps = a.child
        if mode == "export":
            export(int(size), steps)
        else:
            child(mode, int(size), int(steps))
        return
    import torch
    import ultralytics

    print(f"ultralytics {ultralytics.__version__}, torch {torch.__version__}, {THREADS} threads")
    for size in a.sizes:
        t = run_child(["train", str(size), str(a.train_steps)])
        i = run_child(["infer", str(size), str(a.repeats)])
        print(
            f"ultralytics {size} px: train {t['ms']:.1f} ms/img (batch 8; min {t['min']:.1f}, max {t['max']:.1f}), "
            f"{1e3 / t['ms']:.2f} img/s, peak RSS {t['peak_rss_mib']:.0f} MiB; "
            f"inference {i['ms']:.1f} ms (batch 1; min {i['min']:.1f}, max {i['max']:.1f}), peak RSS {i['peak_rss_mib']:.0f} MiB",
            flush=True,
        )
        if a.onnx_dir:
            subprocess.run([sys.executable, __file__, "--child", "export", str(size), a.onnx_dir], check=True,
                           stdout=subprocess.DEVNULL)


if __name__ == "__main__":
    main()
