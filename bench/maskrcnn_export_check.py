"""Checks a Mask R-CNN export of chicktrain against Python's tools (issue 15).

  chicktrain export --checkpoint best.bpk --format onnx --reference
  chicktrain export --checkpoint best.bpk --format safetensors
  python bench/maskrcnn_export_check.py --onnx best.onnx --safetensors best.safetensors

--onnx: runs the three exported graphs (best.onnx: backbone + FPN + RPN head,
best.box_head.onnx, best.mask_head.onnx) in ONNX Runtime on the inputs stored in
best.reference.safetensors and compares every output with chicktrain's own (stored beside
them): max |ORT - chicktrain| per output, must be <= 1e-4.

--safetensors: builds the torchvision model the export names (its `torchvision_builder`
metadata: `maskrcnn_resnet50_fpn(weights=None, weights_backbone=None, num_classes=K)` for
the paper preset at ResNet-50; torchvision's own classes at the stored sizes for compact
presets, which no torchvision builder makes), loads the file with
`load_state_dict(strict=True)`, and, with the reference file, compares torchvision's
eval-mode backbone + FPN (P2-P6), RPN head, box head + predictor and mask head + predictor
with chicktrain's outputs (torchvision's background class first: moved last / dropped for
the comparison). Tolerance: |torchvision - chicktrain| <= 1e-4 * max(1, |chicktrain|).

Prints one line per output and exits 1 if any exceeds its tolerance.
Requirements: bench/requirements.txt (torch, torchvision, onnxruntime, safetensors).
"""

import argparse
import json
import os
import sys

import numpy as np
from safetensors.numpy import load_file

TOL = 1e-4
MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32).reshape(1, 3, 1, 1)
STD = np.array([0.229, 0.224, 0.225], dtype=np.float32).reshape(1, 3, 1, 1)
LEVELS = ["p2", "p3", "p4", "p5", "p6"]


def reference_path(onnx_path):
    root, _ = os.path.splitext(onnx_path)
    return root + ".reference.safetensors"


def report(name, got, want, relative):
    got, want = np.asarray(got, dtype=np.float32), np.asarray(want, dtype=np.float32)
    if got.shape != want.shape:
        print(f"{name}: shape {got.shape} != chicktrain's {want.shape}")
        return False
    diff = np.abs(got - want)
    if relative:
        err = float((diff / np.maximum(1.0, np.abs(want))).max())
        ok = err <= TOL
        print(f"{name} {list(want.shape)}: max abs diff {diff.max():.3e}, max rel diff {err:.3e} {'ok' if ok else 'FAIL'}")
    else:
        err = float(diff.max())
        ok = err <= TOL
        print(f"{name} {list(want.shape)}: max abs diff {err:.3e} {'ok' if ok else 'FAIL'}")
    return ok


def check_onnx(onnx_path, ref):
    import onnxruntime as ort

    root, _ = os.path.splitext(onnx_path)
    graphs = [
        (onnx_path, "images"),
        (root + ".box_head.onnx", "box_features"),
        (root + ".mask_head.onnx", "mask_features"),
    ]
    ok = True
    print(f"ONNX Runtime {ort.__version__}")
    for path, inp in graphs:
        sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
        names = [o.name for o in sess.get_outputs()]
        outs = sess.run(names, {inp: ref[inp]})
        print(f"{os.path.basename(path)}:")
        for n, o in zip(names, outs):
            ok &= report(f"  {n}", o, ref[n], relative=False)
    return ok


def scaled(c, w):
    return max(int(round(c * w / 8.0)), 1) * 8


def build_torchvision(meta):
    import torch
    from torch import nn
    from torchvision.models.detection import MaskRCNN, maskrcnn_resnet50_fpn
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.models.detection.backbone_utils import BackboneWithFPN, resnet_fpn_backbone
    from torchvision.models.detection.faster_rcnn import FastRCNNPredictor, TwoMLPHead
    from torchvision.models.detection.mask_rcnn import MaskRCNNHeads, MaskRCNNPredictor
    from torchvision.models.detection.rpn import RPNHead
    from torchvision.models.resnet import BasicBlock, Bottleneck, ResNet
    from torchvision.ops import misc as misc_nn_ops
    from torchvision.ops.feature_pyramid_network import LastLevelMaxPool

    k = int(meta["num_classes"])
    s = json.loads(meta["chicktrain_maskrcnn"])
    builder = meta.get("torchvision_builder", "none")
    if builder != "none":
        if s["depth"] == 50:
            print(f"torchvision builder: maskrcnn_resnet50_fpn(weights=None, weights_backbone=None, num_classes={k})")
            return maskrcnn_resnet50_fpn(weights=None, weights_backbone=None, num_classes=k)
        print(f"torchvision builder: MaskRCNN(resnet_fpn_backbone('resnet{s['depth']}'), num_classes={k})")
        bb = resnet_fpn_backbone(backbone_name=f"resnet{s['depth']}", weights=None, trainable_layers=5)
        return MaskRCNN(bb, num_classes=k)
    print(f"no torchvision builder for these sizes: torchvision's classes at {s}")
    layers = {18: [2, 2, 2, 2], 34: [3, 4, 6, 3], 50: [3, 4, 6, 3], 101: [3, 4, 23, 3], 152: [3, 8, 36, 3]}[s["depth"]]
    block = BasicBlock if s["depth"] < 50 else Bottleneck
    w = s["width_mult"]
    norm = misc_nn_ops.FrozenBatchNorm2d
    body = ResNet(block, layers, norm_layer=norm)
    stem = scaled(64, w)
    body.inplanes = stem
    body.conv1 = nn.Conv2d(3, stem, kernel_size=7, stride=2, padding=3, bias=False)
    body.bn1 = norm(stem)
    for i in range(4):
        setattr(body, f"layer{i + 1}", body._make_layer(block, scaled(64 << i, w), layers[i], stride=1 if i == 0 else 2))
    in_list = [scaled(64 << i, w) * block.expansion for i in range(4)]
    c = s["fpn_channels"]
    backbone = BackboneWithFPN(
        body,
        return_layers={"layer1": "0", "layer2": "1", "layer3": "2", "layer4": "3"},
        in_channels_list=in_list,
        out_channels=c,
        extra_blocks=LastLevelMaxPool(),
    )
    if s["box_num_fc"] != 2:
        sys.exit(f"box head with {s['box_num_fc']} FCs: torchvision's TwoMLPHead has 2")
    a = len(s["anchor_ratios"])
    anchors = AnchorGenerator(tuple((x,) for x in s["anchor_sizes"]), (tuple(s["anchor_ratios"]),) * len(s["anchor_sizes"]))
    return MaskRCNN(
        backbone,
        num_classes=None,
        rpn_anchor_generator=anchors,
        rpn_head=RPNHead(c, a),
        box_head=TwoMLPHead(c * s["box_pool"] ** 2, s["box_fc_dim"]),
        box_predictor=FastRCNNPredictor(s["box_fc_dim"], k),
        mask_head=MaskRCNNHeads(c, [s["mask_conv_dim"]] * s["mask_num_conv"], 1),
        mask_predictor=MaskRCNNPredictor(s["mask_conv_dim"], s["mask_conv_dim"], k),
    )


def check_safetensors(path, ref):
    import torch
    from safetensors import safe_open
    from safetensors.torch import load_file as load_torch

    with safe_open(path, "pt") as f:
        meta = f.metadata()
    model = build_torchvision(meta)
    sd = load_torch(path)
    missing, unexpected = model.load_state_dict(sd, strict=True)
    print(f"load_state_dict(strict=True): {len(sd)} tensors, missing {list(missing)}, unexpected {list(unexpected)}")
    if ref is None:
        return True
    model.eval()
    ok = True
    t = lambda k: torch.from_numpy(ref[k])
    with torch.no_grad():
        x = (t("images") - torch.from_numpy(MEAN)) / torch.from_numpy(STD)
        feats = model.backbone(x)
        for lvl, v in zip(LEVELS, feats.values()):
            ok &= report(f"  {lvl}", v.numpy(), ref[lvl], relative=True)
        obj, deltas = model.rpn.head(list(feats.values()))
        for lvl, o, d in zip(LEVELS, obj, deltas):
            ok &= report(f"  rpn_objectness.{lvl}", o.numpy(), ref[f"rpn_objectness.{lvl}"], relative=True)
            ok &= report(f"  rpn_deltas.{lvl}", d.numpy(), ref[f"rpn_deltas.{lvl}"], relative=True)
        rh = model.roi_heads
        cls, box = rh.box_predictor(rh.box_head(t("box_features")))
        # torchvision: background first; chicktrain: background last, no background deltas.
        cls = torch.cat([cls[:, 1:], cls[:, :1]], 1)
        ok &= report("  class_logits", cls.numpy(), ref["class_logits"], relative=True)
        ok &= report("  box_deltas", box[:, 4:].numpy(), ref["box_deltas"], relative=True)
        mask = rh.mask_predictor(rh.mask_head(t("mask_features")))
        ok &= report("  mask_logits", mask[:, 1:].numpy(), ref["mask_logits"], relative=True)
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--onnx", help="best.onnx of `chicktrain export --format onnx --reference`")
    ap.add_argument("--safetensors", help="best.safetensors of `chicktrain export --format safetensors`")
    ap.add_argument("--reference", help="reference file (default: beside --onnx)")
    a = ap.parse_args()
    if not a.onnx and not a.safetensors:
        ap.error("give --onnx and/or --safetensors")
    ref_path = a.reference or (reference_path(a.onnx) if a.onnx else None)
    ref = load_file(ref_path) if ref_path else None
    ok = True
    if a.onnx:
        ok &= check_onnx(a.onnx, ref)
    if a.safetensors:
        import torchvision

        print(f"torchvision {torchvision.__version__}: {a.safetensors}")
        ok &= check_safetensors(a.safetensors, ref)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
