"""Checks an ONNX file written by `chicktrain export --format onnx --reference`.

1. `onnx.checker.check_model(full_check=True)`: the graph is valid ONNX (opset, types,
   shape inference).
2. ONNX Runtime (CPU) runs it on the reference input that chicktrain wrote next to the
   file (`<model>.reference.safetensors`) and its outputs are compared with chicktrain's
   own outputs for that input (output0: boxes, scores, mask coefficients; output1:
   prototypes). Passes when every value satisfies |ort - chicktrain| <= tol + tol * |chicktrain|
   (numpy.allclose with rtol = atol = --tol): boxes are in input pixels (up to ~2x the
   input size), where float32 spacing alone is 3e-5 at 256-512 px; scores, coefficients
   and prototypes are below 1, so for them this is the absolute 1e-4. Each part's max
   absolute and relative difference is printed.
3. With --ultralytics, ultralytics' own ONNX backend (`YOLO(model.onnx, task="segment")`)
   loads the file and predicts on the reference input: the file reads like one of its own
   exports (metadata, output layout).

Usage (from the repository root; pinned versions in bench/requirements.txt):
    chicktrain export --checkpoint runs/quickstart/best.bpk --format onnx --reference
    python bench/onnx_check.py runs/quickstart/best.onnx [--ultralytics]
"""

import argparse
import ast
import json
import sys
import time
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from safetensors.numpy import load_file


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", type=Path, help="the exported .onnx file")
    ap.add_argument("--reference", type=Path, help="default: <model>.reference.safetensors")
    ap.add_argument("--tol", type=float, default=1e-4, help="rtol = atol of numpy.allclose")
    ap.add_argument("--threads", type=int, default=2, help="ONNX Runtime intra-op threads")
    ap.add_argument("--ultralytics", action="store_true", help="also predict with ultralytics' ONNX backend")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    a = ap.parse_args()

    ref_path = a.reference or a.model.with_suffix(".reference.safetensors")
    model = onnx.load(str(a.model))
    onnx.checker.check_model(model, full_check=True)
    meta = {p.key: p.value for p in model.metadata_props}
    opset = max(o.version for o in model.opset_import if o.domain in ("", "ai.onnx"))

    ref = load_file(str(ref_path))
    so = ort.SessionOptions()
    so.intra_op_num_threads = a.threads
    sess = ort.InferenceSession(str(a.model), so, providers=["CPUExecutionProvider"])
    names = [o.name for o in sess.get_outputs()]
    t0 = time.perf_counter()
    out = sess.run(None, {"images": ref["images"]})
    ms = (time.perf_counter() - t0) * 1e3
    res = {
        "model": str(a.model),
        "onnx": onnx.__version__,
        "onnxruntime": ort.__version__,
        "opset": opset,
        "checker": "ok",
        "outputs": {},
        "tol": a.tol,
    }
    ok = True
    nc = len(ast.literal_eval(meta["names"])) if "names" in meta else None
    for name, got in zip(names, out):
        want = ref[name]
        if got.shape != want.shape:
            print(f"{name}: shape {got.shape} from ONNX Runtime, {want.shape} from chicktrain", file=sys.stderr)
            return 1
        parts = {"all": (got, want)}
        if name == "output0" and nc is not None:
            parts = {
                "boxes": (got[:, :4], want[:, :4]),
                "scores": (got[:, 4 : 4 + nc], want[:, 4 : 4 + nc]),
                "coefficients": (got[:, 4 + nc :], want[:, 4 + nc :]),
            }
        entry = {"shape": list(got.shape)}
        for part, (g, w) in parts.items():
            d = np.abs(g - w)
            entry[part] = {
                "max_abs_diff": float(d.max()),
                "max_rel_diff": float((d / np.maximum(np.abs(w), 1e-12)).max()),
                "max_abs_value": float(np.abs(w).max()),
            }
        res["outputs"][name] = entry
        ok &= bool(np.allclose(got, want, rtol=a.tol, atol=a.tol))
    res["ort_first_run_ms"] = round(ms, 1)

    if a.ultralytics:
        from ultralytics import YOLO

        y = YOLO(str(a.model), task="segment")
        img = (ref["images"][0].transpose(1, 2, 0)[:, :, ::-1] * 255).round().astype(np.uint8)  # BGR HWC
        r = y.predict(img, imgsz=int(img.shape[0]), conf=0.001, verbose=False)[0]
        res["ultralytics"] = {
            "names": r.names,
            "detections": int(len(r.boxes)),
            "masks": None if r.masks is None else list(r.masks.data.shape),
        }
        res["metadata_task"] = meta.get("task")

    if a.json:
        print(json.dumps(res))
    else:
        print(f"{a.model}: onnx.checker ok (opset {opset}); ONNX Runtime {ort.__version__} vs chicktrain:")
        for k, v in res["outputs"].items():
            for part, e in v.items():
                if part != "shape":
                    print(
                        f"  {k} {v['shape']} {part}: max |diff| {e['max_abs_diff']:.3e}"
                        f" (values up to {e['max_abs_value']:.3g}, max relative diff {e['max_rel_diff']:.2e})"
                    )
        if "ultralytics" in res:
            u = res["ultralytics"]
            print(f"  ultralytics YOLO(onnx) predict: names {u['names']}, {u['detections']} detections, masks {u['masks']}")
        print("PASS" if ok else f"FAIL (tolerance {a.tol})")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
