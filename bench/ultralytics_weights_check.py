"""Does ultralytics take chicktrain's safetensors export and give chicktrain's outputs? And
does chicktrain read full-size ultralytics checkpoints in the released layout?

Export part:

Trains a small YOLO11n-seg-layout checkpoint with chicktrain (2 epochs at 64 px, width x0.5,
so BatchNorm statistics are trained ones), exports it with
`chicktrain export --format safetensors`, builds the same SegmentationModel in ultralytics
from the file's metadata, loads the file with `load_state_dict(..., strict=True)`, and
compares ultralytics' eval-mode raw head outputs (boxes, scores, mask coefficients,
prototypes) with chicktrain's on the same input (`examples/yolo_raw_forward.rs`).

Import part: for yolo11n-seg and yolo11s-seg (nc 80, random init, BatchNorm statistics
randomised), writes a checkpoint as ultralytics' trainer does and turns it into the released
layout with ultralytics' own `strip_optimizer` (the fp16 model object under `model`, `ema`
None, as in the published yolo11n-seg.pt), reads it with chicktrain
(`yolo_raw_forward WEIGHTS.pt ... n 1.0 80`) and compares with ultralytics' forward.

Exits 1 if any output differs by more than 1e-4.

From the repository root, after `cargo test --release --no-run` (it builds the binary and the
example), with the pins of bench/requirements.txt:

    .venv/bin/python bench/ultralytics_weights_check.py --bin target/release/chicktrain

`--checkpoint X.bpk` checks an existing YOLO checkpoint instead of training one.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import copy

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file
from ultralytics.nn.tasks import SegmentationModel, yaml_model_load
from ultralytics.utils.torch_utils import strip_optimizer


def run(cmd):
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)


def compare(ours, theirs, tol):
    worst = 0.0
    for k, v in theirs.items():
        assert ours[k].shape == v.shape, (k, ours[k].shape, v.shape)
        d = (ours[k] - v).abs().max().item()
        worst = max(worst, d)
        print(f"  {k:17s} {str(tuple(v.shape)):18s} max |chicktrain - ultralytics| = {d:.3g}  (max |value| {v.abs().max().item():.3g})")
    print(f"  worst {worst:.3g}, tolerance {tol:g}: {'OK' if worst <= tol else 'FAIL'}")
    return worst <= tol


def raw_outputs(model, images):
    with torch.no_grad():
        (_, proto), preds = model(images)
    return {"boxes": preds["boxes"], "scores": preds["scores"],
            "mask_coefficient": preds["mask_coefficient"], "proto": proto}


@torch.no_grad()
def import_check(example, work, scale, tol):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    model = SegmentationModel(yaml_model_load(f"yolo11{scale}-seg.yaml"), ch=3, nc=80, verbose=False)
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            n = m.num_features
            m.running_mean.copy_(torch.randn(n, generator=g) * 0.2)
            m.running_var.copy_(torch.rand(n, generator=g) + 0.5)
            m.weight.copy_(torch.rand(n, generator=g) + 0.5)
            m.bias.copy_(torch.randn(n, generator=g) * 0.1)
    f = os.path.join(work, f"yolo11{scale}-seg-released.pt")
    torch.save({"epoch": 0, "best_fitness": None, "model": None, "ema": copy.deepcopy(model).half(),
                "updates": 0, "optimizer": None, "train_args": {"model": f"yolo11{scale}-seg.yaml"}}, f)
    strip_optimizer(f)  # ultralytics' own step from last.pt to a released file
    ckpt = torch.load(f, weights_only=False)
    assert ckpt["ema"] is None and ckpt["model"] is not None
    images = torch.rand(1, 3, 96, 128, generator=torch.Generator().manual_seed(2))
    inp = os.path.join(work, f"input_{scale}.safetensors")
    save_file({"images": images}, inp)
    out = os.path.join(work, f"chicktrain_{scale}.safetensors")
    run([example, f, inp, out, scale, "1.0", "80"])
    print(f"yolo11{scale}-seg, nc 80, released layout ({os.path.getsize(f) / 1e6:.1f} MB):")
    return compare(load_file(out), raw_outputs(ckpt["model"].float().eval(), images), tol)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/chicktrain")
    ap.add_argument("--example", default=None, help="yolo_raw_forward (default: beside --bin, examples/)")
    ap.add_argument("--checkpoint", default=None)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--part", choices=["export", "import", "both"], default="both")
    a = ap.parse_args()
    example = a.example or os.path.join(os.path.dirname(a.bin), "examples", "yolo_raw_forward")
    work = a.workdir or tempfile.mkdtemp(prefix="ct-ultra-check-")
    os.makedirs(work, exist_ok=True)

    ok = True
    if a.part in ("import", "both"):
        for scale in ("n", "s"):
            ok &= import_check(example, work, scale, a.tol)
    if a.part == "import":
        sys.exit(0 if ok else 1)

    ckpt = a.checkpoint
    if ckpt is None:
        run_dir = os.path.join(work, "run")
        run([a.bin, "--config", "yolo_real_baseline.toml", "--run-dir", run_dir,
             "--set", "train.epochs=2", "--set", "data.real.count=12", "--set", "data.synthetic=8",
             "--set", "data.image_size=64", "--set", "data.crop=64", "--set", "model.width_mult=0.5",
             "--set", f'data.cache="{os.path.join(work, "cache")}"'])
        ckpt = os.path.join(run_dir, "best.bpk")
    st = os.path.join(work, "best.safetensors")
    run([a.bin, "export", "--checkpoint", ckpt, "--format", "safetensors", "--out", st])

    with safe_open(st, "pt") as f:
        meta = f.metadata()
    print("metadata:", meta)
    cfg = yaml_model_load(meta["architecture"])
    cfg["scales"]["chicktrain"] = json.loads(meta["ultralytics_scale"])
    cfg["scale"] = "chicktrain"
    nc, nm = int(meta["nc"]), int(meta["nm"])
    cfg["head"][-1][-1][1] = nm  # Segment [nc, nm, npr]
    model = SegmentationModel(cfg, ch=3, nc=nc, verbose=False)
    result = model.load_state_dict(load_file(st), strict=True)
    print("load_state_dict(strict=True):", result)
    model.eval()

    images = torch.rand(2, 3, 64, 96, generator=torch.Generator().manual_seed(0))
    inp = os.path.join(work, "input.safetensors")
    save_file({"images": images}, inp)
    out = os.path.join(work, "chicktrain_out.safetensors")
    run([example, ckpt, inp, out])
    print("chicktrain checkpoint -> safetensors -> ultralytics:")
    ok &= compare(load_file(out), raw_outputs(model, images), a.tol)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
