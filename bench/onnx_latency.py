"""Batch-1 latency of ONNX files in ONNX Runtime (CPU), for the same weights chicktrain
times on flex and tract: `chicktrain bench engines --save-onnx DIR` writes them.

Usage (pinned versions in bench/requirements.txt):
    chicktrain bench engines --variants yolo-n --sizes 256,640 --save-onnx runs/engines
    python bench/onnx_latency.py runs/engines/*.onnx --runs 20 --threads 2

Prints, per file: median, p10 and p90 of `--runs` `InferenceSession.run` calls after 2
warm-up runs, with `intra_op_num_threads = --threads` (the issue-16 protocol).
"""

import argparse
import time

import numpy as np
import onnxruntime as ort


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("models", nargs="+")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    print(f"onnxruntime {ort.__version__}, {a.threads} intra-op threads, {a.runs} runs after 2 warm-up")
    for m in a.models:
        so = ort.SessionOptions()
        so.intra_op_num_threads = a.threads
        s = ort.InferenceSession(m, so, providers=["CPUExecutionProvider"])
        shape = [d if isinstance(d, int) else 1 for d in s.get_inputs()[0].shape]
        x = np.random.default_rng(0).random(shape, dtype=np.float32)
        t = []
        for r in range(2 + a.runs):
            t0 = time.perf_counter()
            s.run(None, {"images": x})
            if r >= 2:
                t.append((time.perf_counter() - t0) * 1e3)
        p10, p50, p90 = np.percentile(t, [10, 50, 90])
        print(f"{m}: {p50:.1f} ms (p10 {p10:.1f}, p90 {p90:.1f})")


if __name__ == "__main__":
    main()
