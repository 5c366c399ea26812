"""ONNX Runtime's time for every convolution shape `chicktrain bench convs` times (issue 37),
beside flex's: the column "ONNX Runtime per node" of the convolution table.

Reads the `convs.csv` of one `chicktrain bench convs` run, builds for each distinct forward
shape a one-node ONNX model (Conv with bias, pads k/2, the same batch), and times it in ONNX
Runtime (CPU, `--threads` intra-op threads, all graph optimisations, so MLAS picks its NCHWc
kernels as it does inside a whole model). Two times per shape, medians over `--runs` after
3 warm-up runs:
  - node: the Conv node's own time from ONNX Runtime's profiler (`enable_profiling`), what
    the node costs inside a whole model; layout reorders MLAS inserts at a one-node graph's
    edges are reported apart (in a whole model they happen once, at its edges);
  - run: the whole `InferenceSession.run` call, reorders and call overhead included.
Then joins them with flex's forward rows: flex ms ÷ ONNX Runtime node ms per shape and
summed per model and size, each shape weighted by its layer count.

Usage (pinned versions in bench/requirements.txt), right after the bench on the same box:
    chicktrain bench convs --sizes 256,640 --out OUT
    python bench/convs/ort_convs.py OUT/convs.csv --threads 2 --out OUT
writes OUT/ort_convs.csv and OUT/ort_convs.md.
"""

import argparse
import csv
import json
import os
import platform
import statistics
import tempfile
import time
from collections import defaultdict

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper

from convs_csv import used_ms as flex_ms


def conv_model(c_in, c_out, k, stride, groups, hw, batch):
    """A graph with one Conv node (bias, pads k/2, dilation 1) on a fixed input shape."""
    rng = np.random.default_rng(0)
    w = rng.standard_normal((c_out, c_in // groups, k, k), dtype=np.float32) * 0.1
    b = rng.standard_normal((c_out,), dtype=np.float32) * 0.1
    p = k // 2
    node = helper.make_node(
        "Conv", ["x", "w", "b"], ["y"], kernel_shape=[k, k], strides=[stride, stride],
        pads=[p, p, p, p], group=groups, name="conv",
    )
    o = (hw + 2 * p - k) // stride + 1
    g = helper.make_graph(
        [node], "conv",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [batch, c_in, hw, hw])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [batch, c_out, o, o])],
        [numpy_helper.from_array(w, "w"), numpy_helper.from_array(b, "b")],
    )
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
    m.ir_version = 8
    onnx.checker.check_model(m)
    return m


def time_shape(model, x, threads, runs, tmp):
    """(median node ms of the Conv kernel, median reorder ms, median run ms, kernel names)."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.enable_profiling = True
    so.profile_file_prefix = os.path.join(tmp, "prof")
    s = ort.InferenceSession(model.SerializeToString(), so, providers=["CPUExecutionProvider"])
    wall = []
    for r in range(3 + runs):
        t0 = time.perf_counter()
        s.run(None, {"x": x})
        if r >= 3:
            wall.append((time.perf_counter() - t0) * 1e3)
    path = s.end_profiling()
    with open(path) as f:
        events = json.load(f)
    os.remove(path)
    # Node events: cat "Node", name "<node>_kernel_time"; one per node per run.
    per_node = defaultdict(list)
    ops = {}
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            n = e["name"][: -len("_kernel_time")]
            per_node[n].append(e["dur"] / 1e3)
            ops[n] = e.get("args", {}).get("op_name", "?")
    conv = [n for n in per_node if "Conv" in ops[n]]
    other = [n for n in per_node if n not in conv]
    if len(conv) != 1:
        raise SystemExit(f"expected one Conv node in the optimised graph, got {conv} ({ops})")
    node = per_node[conv[0]][-runs:]
    reorder = [sum(v) for v in zip(*(per_node[n][-runs:] for n in other))] if other else [0.0]
    return statistics.median(node), statistics.median(reorder), statistics.median(wall), ops


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("convs_csv")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--batch", type=int, default=None, help="default: the bench's (from the folder's convs.md)")
    ap.add_argument("--out", default=None, help="default: the folder of convs_csv")
    a = ap.parse_args()
    out = a.out or os.path.dirname(a.convs_csv)
    with open(a.convs_csv) as f:
        rows = [r for r in csv.DictReader(f) if r["pass"] == "forward"]
    batch = a.batch
    if batch is None:
        md = os.path.join(os.path.dirname(a.convs_csv), "convs.md")
        with open(md) as f:
            head = f.readline()
        if not head.startswith("Batch "):
            raise SystemExit(f"{md} does not start with 'Batch N': pass --batch")
        batch = int(head.split()[1].rstrip(","))
    shapes = {}
    for r in rows:
        key = tuple(int(r[c]) for c in ("c_in", "c_out", "k", "stride", "groups", "hw"))
        shapes.setdefault(key, None)
    tmp = tempfile.mkdtemp(prefix="ort_convs_")
    load0 = os.getloadavg()
    kernels = {}
    for key in shapes:
        c_in, c_out, k, stride, groups, hw = key
        x = np.random.default_rng(1).standard_normal((batch, c_in, hw, hw), dtype=np.float32)
        node, reorder, wall, ops = time_shape(conv_model(*key, batch), x, a.threads, a.runs, tmp)
        shapes[key] = (node, reorder, wall)
        kernels[key] = ",".join(sorted(set(ops.values())))
    load1 = os.getloadavg()
    os.rmdir(tmp)

    with open(os.path.join(out, "ort_convs.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["model", "size", "name", "c_in", "c_out", "k", "stride", "groups", "hw", "count",
                    "gflop", "flex_ms", "ort_node_ms", "ort_reorder_ms", "ort_run_ms", "ort_ops",
                    "ort_node_gflops", "flex_over_ort_node"])
        for r in rows:
            key = tuple(int(r[c]) for c in ("c_in", "c_out", "k", "stride", "groups", "hw"))
            node, reorder, wall = shapes[key]
            gflop = float(r["gflop"])
            w.writerow([r["model"], r["size"], r["name"], *key[:5], key[5], r["count"], r["gflop"],
                        f"{flex_ms(r):.4f}", f"{node:.4f}", f"{reorder:.4f}", f"{wall:.4f}", kernels[key],
                        f"{gflop / node * 1e3:.2f}", f"{flex_ms(r) / node:.3f}"])

    lines = [
        f"Batch {batch}, f32, forward. ONNX Runtime {ort.__version__} ({a.threads} intra-op threads, "
        f"ORT_ENABLE_ALL), one Conv node per shape, median of {a.runs} runs after 3 warm-up; "
        f"python {platform.python_version()}; load average {load0[0]:.2f} before, {load1[0]:.2f} after.",
        "",
        "flex ms: what flex's conv2d runs now, from the same folder's convs.md (the engine, or the "
        "old path where `fwd→engine` is false). "
        "node: the Conv kernel's time from ONNX Runtime's profiler; reorder: the layout "
        "conversions MLAS adds around a one-node graph (in a whole model only at its edges); "
        "run: the whole session.run call.",
        "",
        "| model | size | conv | shape | ×n | flex ms | ORT node ms | ORT reorder ms | ORT run ms | ORT kernel | ORT node GFLOP/s | flex ÷ ORT node |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    totals = defaultdict(lambda: [0.0, 0.0, 0.0, 0.0])
    for r in rows:
        key = tuple(int(r[c]) for c in ("c_in", "c_out", "k", "stride", "groups", "hw"))
        node, reorder, wall = shapes[key]
        c_in, c_out, k, stride, groups, hw = key
        n = int(r["count"])
        flex = flex_ms(r)
        gflop = float(r["gflop"])
        t = totals[(r["model"], r["size"])]
        t[0] += n * flex
        t[1] += n * node
        t[2] += n * gflop
        t[3] += n * wall
        lines.append(
            f"| {r['model']} | {r['size']} | {r['name']} | {c_in}→{c_out} {k}×{k} s{stride} g{groups} @{hw} | {n} "
            f"| {flex:.3f} | {node:.3f} | {reorder:.3f} | {wall:.3f} | {kernels[key]} | {gflop / node * 1e3:.1f} | {flex / node:.2f} |"
        )
    lines += [
        "",
        "Totals, each shape weighted by its layer count:",
        "",
        "| model | size | flex ms | ORT node ms | flex GFLOP/s | ORT node GFLOP/s | flex ÷ ORT node | ORT run ms (sum) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (model, size), (flex, node, gflop, wall) in totals.items():
        lines.append(
            f"| {model} | {size} | {flex:.2f} | {node:.2f} | {gflop / flex * 1e3:.1f} | {gflop / node * 1e3:.1f} "
            f"| {flex / node:.2f} | {wall:.2f} |"
        )
    with open(os.path.join(out, "ort_convs.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines[-(len(totals) + 4):]))


if __name__ == "__main__":
    main()
