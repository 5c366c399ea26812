//! ONNX export of YOLO-seg in ultralytics' layout, so that tools written for
//! `yolo export format=onnx` files read ours.
//!
//! The graph is the eval-mode inference path with every BatchNorm folded into its conv
//! (the model is fused here), opset 17, and ultralytics 8.4's `Segment` export outputs:
//!
//! - `images` `[B, 3, H, W]`, RGB in [0, 1];
//! - `output0` `[B, 4 + nc + nm, A]`: boxes as centre-x, centre-y, width, height in input
//!   pixels (DFL expectation, `dist2bbox(xywh=True)`, × stride), class scores after the
//!   sigmoid, raw mask coefficients; anchors finest level first, row-major;
//! - `output1` `[B, nm, H/4, W/4]` (with P3 heads): the mask prototypes.
//!
//! `B` is fixed, or the symbol `batch` with `dynamic`. H and W are fixed: the anchor grid
//! is baked in as constants (ultralytics' `dynamic=True` also frees H and W; we do not).
//! The metadata keys ultralytics' `AutoBackend` reads (`task`, `stride`, `imgsz`,
//! `batch`, `names`, …) are written as it writes them (Python literals, `onnx_metadata`).

use anyhow::{ensure, Result};
use burn::nn::PaddingConfig2d;

use super::attention::{Attention, C2psa, PsaBlock};
use super::backbone::Backbone;
use super::blocks::{Bottleneck, C3k, C3k2, C3k2Inner, ConvBn, Proto, Sppf};
use super::head::REG_MAX;
use super::neck::Neck;
use super::onnx_metadata::metadata;
use super::{AnchorGrid, YoloOutput, YoloSeg};
use crate::model::onnx::graph::{Dim, GraphBuilder};
use crate::model::onnx::layers::conv2d;
use crate::util::tensor::to_host;

/// What the exported file looks like beyond the weights.
#[derive(Debug, Clone)]
pub struct OnnxExportOptions {
    /// Batch size of a static graph, and the `batch` metadata entry.
    pub batch: usize,
    /// A symbolic batch dimension (`batch`) instead of `batch`.
    pub dynamic: bool,
    /// Class names, index = class id (written to the `names` metadata).
    pub names: Vec<String>,
    /// COCO category id of each class (chicktrain's own metadata entry, so that
    /// `predict --onnx` writes the checkpoint's ids).
    pub category_ids: Vec<u64>,
}

/// ultralytics `Conv` after `fuse()`: conv with the folded bias, then SiLU.
fn conv_bn(g: &mut GraphBuilder, scope: &str, x: &str, c: &ConvBn) -> Result<String> {
    ensure!(
        c.fused,
        "{scope}: BatchNorm not folded (export a fused model)"
    );
    let y = conv2d(g, &format!("{scope}/conv"), x, &c.conv)?;
    Ok(if c.act {
        g.silu(&format!("{scope}/act"), &y)
    } else {
        y
    })
}

fn bottleneck(g: &mut GraphBuilder, scope: &str, x: &str, b: &Bottleneck) -> Result<String> {
    let y = conv_bn(g, &format!("{scope}/cv1"), x, &b.cv1)?;
    let y = conv_bn(g, &format!("{scope}/cv2"), &y, &b.cv2)?;
    Ok(if b.add {
        g.binary(scope, "Add", x, &y)
    } else {
        y
    })
}

fn c3k(g: &mut GraphBuilder, scope: &str, x: &str, c: &C3k) -> Result<String> {
    let mut a = conv_bn(g, &format!("{scope}/cv1"), x, &c.cv1)?;
    for (i, b) in c.m.iter().enumerate() {
        a = bottleneck(g, &format!("{scope}/m.{i}"), &a, b)?;
    }
    let b = conv_bn(g, &format!("{scope}/cv2"), x, &c.cv2)?;
    let y = g.concat(scope, &[&a, &b], 1);
    conv_bn(g, &format!("{scope}/cv3"), &y, &c.cv3)
}

fn c3k2(g: &mut GraphBuilder, scope: &str, x: &str, c: &C3k2) -> Result<String> {
    let y = conv_bn(g, &format!("{scope}/cv1"), x, &c.cv1)?;
    let mut parts = g.split(scope, &y, 1, &[c.c, c.c]);
    for (i, inner) in c.m.iter().enumerate() {
        let s = format!("{scope}/m.{i}");
        let last = parts.last().expect("two halves").clone();
        let next = match inner {
            C3k2Inner::Bottleneck(b) => bottleneck(g, &s, &last, b)?,
            C3k2Inner::C3k(k) => c3k(g, &s, &last, k)?,
        };
        parts.push(next);
    }
    let refs: Vec<&str> = parts.iter().map(String::as_str).collect();
    let y = g.concat(scope, &refs, 1);
    conv_bn(g, &format!("{scope}/cv2"), &y, &c.cv2)
}

fn sppf(g: &mut GraphBuilder, scope: &str, x: &str, s: &Sppf) -> Result<String> {
    let a = conv_bn(g, &format!("{scope}/cv1"), x, &s.cv1)?;
    let [k, _] = s.pool.kernel_size;
    let pad = match &s.pool.padding {
        PaddingConfig2d::Explicit(p, ..) => *p,
        _ => k / 2,
    };
    let b = g.max_pool(&format!("{scope}/m"), &a, k, s.pool.stride[0], pad);
    let c = g.max_pool(&format!("{scope}/m"), &b, k, s.pool.stride[0], pad);
    let d = g.max_pool(&format!("{scope}/m"), &c, k, s.pool.stride[0], pad);
    let y = g.concat(scope, &[&a, &b, &c, &d], 1);
    conv_bn(g, &format!("{scope}/cv2"), &y, &s.cv2)
}

/// ultralytics `Attention.forward` on a `[B, C, h, w]` map.
fn attention(
    g: &mut GraphBuilder,
    scope: &str,
    x: &str,
    a: &Attention,
    [h, w]: [usize; 2],
) -> Result<String> {
    let (nh, kd, hd) = (a.num_heads as i64, a.key_dim, a.head_dim);
    let c = a.num_heads * hd;
    let qkv = conv_bn(g, &format!("{scope}/qkv"), x, &a.qkv)?;
    let qkv = g.reshape(scope, &qkv, &[0, nh, (2 * kd + hd) as i64, -1]);
    let qkv = g.split(scope, &qkv, 2, &[kd, kd, hd]);
    let (q, k, v) = (&qkv[0], &qkv[1], &qkv[2]);
    let qt = g.transpose(scope, q, &[0, 1, 3, 2]);
    let attn = g.binary(scope, "MatMul", &qt, k);
    let attn = g.mul_scalar(scope, &attn, (kd as f32).powf(-0.5));
    let attn = g.softmax(scope, &attn, -1);
    let attn_t = g.transpose(scope, &attn, &[0, 1, 3, 2]);
    let out = g.binary(scope, "MatMul", v, &attn_t);
    let shape = [0, c as i64, h as i64, w as i64];
    let out = g.reshape(scope, &out, &shape);
    let v_map = g.reshape(scope, v, &shape);
    let pe = conv_bn(g, &format!("{scope}/pe"), &v_map, &a.pe)?;
    let out = g.binary(scope, "Add", &out, &pe);
    conv_bn(g, &format!("{scope}/proj"), &out, &a.proj)
}

fn psa_block(
    g: &mut GraphBuilder,
    scope: &str,
    x: &str,
    p: &PsaBlock,
    hw: [usize; 2],
) -> Result<String> {
    let a = attention(g, &format!("{scope}/attn"), x, &p.attn, hw)?;
    let x = g.binary(scope, "Add", x, &a);
    let f = conv_bn(g, &format!("{scope}/ffn.0"), &x, &p.ffn1)?;
    let f = conv_bn(g, &format!("{scope}/ffn.1"), &f, &p.ffn2)?;
    Ok(g.binary(scope, "Add", &x, &f))
}

fn c2psa(g: &mut GraphBuilder, scope: &str, x: &str, c: &C2psa, hw: [usize; 2]) -> Result<String> {
    let y = conv_bn(g, &format!("{scope}/cv1"), x, &c.cv1)?;
    let parts = g.split(scope, &y, 1, &[c.c, c.c]);
    let mut b = parts[1].clone();
    for (i, blk) in c.m.iter().enumerate() {
        b = psa_block(g, &format!("{scope}/m.{i}"), &b, blk, hw)?;
    }
    let y = g.concat(scope, &[&parts[0], &b], 1);
    conv_bn(g, &format!("{scope}/cv2"), &y, &c.cv2)
}

fn proto(g: &mut GraphBuilder, scope: &str, x: &str, p: &Proto) -> Result<String> {
    let y = conv_bn(g, &format!("{scope}/cv1"), x, &p.cv1)?;
    let up = &p.upsample;
    ensure!(
        up.padding == [0, 0] && up.padding_out == [0, 0] && up.groups == 1 && up.dilation == [1, 1],
        "{scope}: only an unpadded, ungrouped transposed conv is exported"
    );
    let dims = up.weight.dims();
    let w = to_host(up.weight.val());
    let b = up.bias.as_ref().map(|b| to_host(b.val()));
    let y = g.conv_transpose(
        &format!("{scope}/upsample"),
        &y,
        (&dims, &w),
        b.as_deref(),
        up.stride,
    );
    let y = conv_bn(g, &format!("{scope}/cv2"), &y, &p.cv2)?;
    conv_bn(g, &format!("{scope}/cv3"), &y, &p.cv3)
}

/// The ONNX model of `model` (eval mode, not necessarily fused) at `input = [H, W]`.
pub fn export_yolo(
    model: &YoloSeg,
    input: [usize; 2],
    opts: &OnnxExportOptions,
) -> Result<tract_onnx::pb::ModelProto> {
    let [h, w] = input;
    ensure!(
        h > 0 && w > 0 && h % 32 == 0 && w % 32 == 0,
        "ONNX export: input {h}×{w} must be positive multiples of 32"
    );
    ensure!(
        opts.batch > 0,
        "ONNX export: batch must be ≥ 1, got {}",
        opts.batch
    );
    let nc = model.num_classes();
    ensure!(
        opts.names.len() == nc,
        "ONNX export: {} class names for a model with {nc} classes",
        opts.names.len()
    );
    let m = model.clone().fuse();
    let nm = m.head.num_masks;
    let batch = if opts.dynamic {
        Dim::Named("batch".into())
    } else {
        Dim::Fixed(opts.batch)
    };
    let mut g = GraphBuilder::new();
    let x = g.input(
        "images",
        &[batch.clone(), Dim::Fixed(3), Dim::Fixed(h), Dim::Fixed(w)],
    );
    let [p3, p4, p5] = backbone(&mut g, &m.backbone, &x, input)?;
    let feats = neck(&mut g, &m.neck, [p3, p4, p5])?;
    let (proto_out, out0) = segment_head(&mut g, &m, &feats, input)?;

    // Prototypes are at twice the finest head level's resolution.
    let na = AnchorGrid::new(input, &m.strides).num_anchors();
    let (ph, pw) = (h * 2 / m.strides[0], w * 2 / m.strides[0]);
    g.output(
        &out0,
        "output0",
        &[batch.clone(), Dim::Fixed(4 + nc + nm), Dim::Fixed(na)],
    );
    g.output(
        &proto_out,
        "output1",
        &[batch, Dim::Fixed(nm), Dim::Fixed(ph), Dim::Fixed(pw)],
    );
    let meta = metadata(
        &opts.names,
        &opts.category_ids,
        (opts.batch, opts.dynamic),
        &m.strides,
        input,
    );
    g.finish("chicktrain_yolo_seg", &meta)
}

/// The backbone as `Backbone::forward` (ultralytics layer indices in the scopes:
/// /model.0 … /model.10): P3, P4 and P5.
fn backbone(
    g: &mut GraphBuilder,
    bb: &Backbone,
    x: &str,
    [h, w]: [usize; 2],
) -> Result<[String; 3]> {
    let y = conv_bn(g, "/model.0", x, &bb.l0)?;
    let y = conv_bn(g, "/model.1", &y, &bb.l1)?;
    let y = c3k2(g, "/model.2", &y, &bb.l2)?;
    let y = conv_bn(g, "/model.3", &y, &bb.l3)?;
    let p3 = c3k2(g, "/model.4", &y, &bb.l4)?;
    let y = conv_bn(g, "/model.5", &p3, &bb.l5)?;
    let p4 = c3k2(g, "/model.6", &y, &bb.l6)?;
    let y = conv_bn(g, "/model.7", &p4, &bb.l7)?;
    let y = c3k2(g, "/model.8", &y, &bb.l8)?;
    let mut p5 = sppf(g, "/model.9", &y, &bb.sppf)?;
    if let Some(psa) = &bb.psa {
        p5 = c2psa(g, "/model.10", &p5, psa, [h / 32, w / 32])?;
    }
    Ok([p3, p4, p5])
}

/// The neck as `Neck::forward` (/model.11 … /model.22): the head's inputs, finest first.
fn neck(g: &mut GraphBuilder, n: &Neck, [p3, p4, p5]: [String; 3]) -> Result<Vec<String>> {
    let up = g.upsample2x("/model.11", &p5);
    let cat = g.concat("/model.12", &[&up, &p4], 1);
    let p4_td = c3k2(g, "/model.13", &cat, &n.td_p4)?;
    let (mut feats, p4_out) = match &n.p3 {
        Some(n3) => {
            let up = g.upsample2x("/model.14", &p4_td);
            let cat = g.concat("/model.15", &[&up, &p3], 1);
            let p3_out = c3k2(g, "/model.16", &cat, &n3.td_p3)?;
            let d = conv_bn(g, "/model.17", &p3_out, &n3.down_p3)?;
            let cat = g.concat("/model.18", &[&d, &p4_td], 1);
            let p4_out = c3k2(g, "/model.19", &cat, &n3.bu_p4)?;
            (vec![p3_out], p4_out)
        }
        None => (Vec::new(), p4_td),
    };
    let d = conv_bn(g, "/model.20", &p4_out, &n.down_p4)?;
    let cat = g.concat("/model.21", &[&d, &p5], 1);
    let p5_out = c3k2(g, "/model.22", &cat, &n.bu_p5)?;
    feats.push(p4_out);
    feats.push(p5_out);
    Ok(feats)
}

/// The segment head (/model.23; ultralytics: cv2 boxes, cv3 classes, cv4 coefficients,
/// proto) with its decoding: the prototypes and `output0` (boxes, scores, coefficients).
fn segment_head(
    g: &mut GraphBuilder,
    m: &YoloSeg,
    feats: &[String],
    input: [usize; 2],
) -> Result<(String, String)> {
    let hd = &m.head;
    let (nc, nm) = (m.num_classes(), hd.num_masks);
    let s = "/model.23";
    let proto_out = proto(g, &format!("{s}/proto"), &feats[0], &hd.proto)?;
    let (mut boxes, mut cls, mut coef) = (Vec::new(), Vec::new(), Vec::new());
    for (l, f) in feats.iter().enumerate() {
        let b = &hd.boxes[l];
        let sc = format!("{s}/cv2.{l}");
        let y = conv_bn(g, &format!("{sc}/0"), f, &b.c1)?;
        let y = conv_bn(g, &format!("{sc}/1"), &y, &b.c2)?;
        let y = conv2d(g, &format!("{sc}/2"), &y, &b.out)?;
        boxes.push(g.reshape(&sc, &y, &[0, (4 * REG_MAX) as i64, -1]));
        let c = &hd.cls[l];
        let sc = format!("{s}/cv3.{l}");
        let y = conv_bn(g, &format!("{sc}/0/0"), f, &c.dw1)?;
        let y = conv_bn(g, &format!("{sc}/0/1"), &y, &c.pw1)?;
        let y = conv_bn(g, &format!("{sc}/1/0"), &y, &c.dw2)?;
        let y = conv_bn(g, &format!("{sc}/1/1"), &y, &c.pw2)?;
        let y = conv2d(g, &format!("{sc}/2"), &y, &c.out)?;
        cls.push(g.reshape(&sc, &y, &[0, nc as i64, -1]));
        let k = &hd.coef[l];
        let sc = format!("{s}/cv4.{l}");
        let y = conv_bn(g, &format!("{sc}/0"), f, &k.c1)?;
        let y = conv_bn(g, &format!("{sc}/1"), &y, &k.c2)?;
        let y = conv2d(g, &format!("{sc}/2"), &y, &k.out)?;
        coef.push(g.reshape(&sc, &y, &[0, nm as i64, -1]));
    }
    let cat = |g: &mut GraphBuilder, v: &[String]| {
        let r: Vec<&str> = v.iter().map(String::as_str).collect();
        g.concat(s, &r, 2)
    };
    let boxes = cat(g, &boxes);
    let cls = cat(g, &cls);
    let coef = cat(g, &coef);
    let dbox = decode_boxes(g, s, &boxes, &AnchorGrid::new(input, &m.strides));
    let scores = g.sigmoid(s, &cls);
    let out0 = g.concat(s, &[&dbox, &scores, &coef], 1);
    Ok((proto_out, out0))
}

/// The head's box distributions `[B, 4·16, A]` as xywh boxes in input pixels: DFL as
/// ultralytics' `DFL.forward` (softmax over the 16 bins, then a fixed 1×1 conv with
/// weights 0…15, the expectation), then `dist2bbox(xywh=True)` × strides.
fn decode_boxes(g: &mut GraphBuilder, s: &str, boxes: &str, grid: &AnchorGrid) -> String {
    let na = grid.num_anchors();
    let sd = format!("{s}/dfl");
    let y = g.reshape(&sd, boxes, &[0, 4, REG_MAX as i64, -1]);
    let y = g.transpose(&sd, &y, &[0, 2, 1, 3]);
    let y = g.softmax(&sd, &y, 1);
    let bins: Vec<f32> = (0..REG_MAX).map(|r| r as f32).collect();
    let y = g.conv(
        &format!("{sd}/conv"),
        &y,
        (&[1, REG_MAX, 1, 1], &bins),
        None,
        [1, 1],
        [0, 0],
        1,
    );
    let dist = g.reshape(&sd, &y, &[0, 4, -1]);
    // Anchors `[2, A]` in grid units.
    let points = grid.points();
    let mut anchors = vec![0f32; 2 * na];
    for (a, p) in points.iter().enumerate() {
        anchors[a] = p[0];
        anchors[na + a] = p[1];
    }
    let anchors = g.constant_f32(&format!("{s}.anchors"), &[2, na], &anchors);
    let strides = g.constant_f32(&format!("{s}.strides"), &[1, na], &grid.strides());
    let lt_rb = g.split(s, &dist, 1, &[2, 2]);
    let x1y1 = g.binary(s, "Sub", &anchors, &lt_rb[0]);
    let x2y2 = g.binary(s, "Add", &anchors, &lt_rb[1]);
    let sum = g.binary(s, "Add", &x1y1, &x2y2);
    let two = g.constant_f32(&format!("{s}.two"), &[], &[2.0]);
    let c_xy = g.binary(s, "Div", &sum, &two);
    let wh = g.binary(s, "Sub", &x2y2, &x1y1);
    let xywh = g.concat(s, &[&c_xy, &wh], 1);
    g.binary(s, "Mul", &xywh, &strides)
}

/// The ultralytics export layout of a forward pass, computed on the host from the raw
/// outputs the postprocess reads: `output0` `[B, 4 + nc + nm, A]` (row-major) — the
/// reference an exported file must reproduce.
pub fn ultralytics_output0(out: &YoloOutput) -> (Vec<f32>, [usize; 3]) {
    let [b, nc, na] = out.cls_logits.dims();
    let nm = out.mask_coef.dims()[1];
    let dist = to_host(out.box_dist.clone());
    let logits = to_host(out.cls_logits.clone());
    let coef = to_host(out.mask_coef.clone());
    let points = out.grid.points();
    let strides = out.grid.strides();
    let no = 4 + nc + nm;
    let mut y = vec![0f32; b * no * na];
    for i in 0..b {
        for a in 0..na {
            let mut d = [0f32; 4];
            for (k, dk) in d.iter_mut().enumerate() {
                let at = |r: usize| dist[((i * 4 + k) * REG_MAX + r) * na + a];
                let mx = (0..REG_MAX).map(at).fold(f32::NEG_INFINITY, f32::max);
                let (mut num, mut den) = (0f32, 0f32);
                for r in 0..REG_MAX {
                    let e = (at(r) - mx).exp();
                    num += r as f32 * e;
                    den += e;
                }
                *dk = num / den;
            }
            let (p, s) = (points[a], strides[a]);
            let (x1, y1, x2, y2) = (p[0] - d[0], p[1] - d[1], p[0] + d[2], p[1] + d[3]);
            let base = i * no * na + a;
            y[base] = (x1 + x2) / 2.0 * s;
            y[base + na] = (y1 + y2) / 2.0 * s;
            y[base + 2 * na] = (x2 - x1) * s;
            y[base + 3 * na] = (y2 - y1) * s;
            for c in 0..nc {
                let l = logits[(i * nc + c) * na + a];
                y[base + (4 + c) * na] = 1.0 / (1.0 + (-l).exp());
            }
            for k in 0..nm {
                y[base + (4 + nc + k) * na] = coef[(i * nm + k) * na + a];
            }
        }
    }
    (y, [b, no, na])
}

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use burn::tensor::{Device, Distribution, Tensor, TensorData};

    use super::*;
    use crate::model::onnx::engine::TractEngine;
    use crate::model::onnx::graph::encode;
    use crate::model::yolo::{HeadLevels, Scale, YoloSegConfig};

    /// A small random YOLO in eval mode whose BatchNorms hold non-trivial running
    /// statistics (two train-mode passes), so folding them is really tested.
    fn small_model(levels: HeadLevels, c2psa: bool, seed: u64) -> YoloSeg {
        let ad = Device::flex().autodiff();
        ad.seed(seed);
        let m = YoloSegConfig::new(Scale::N, 2)
            .with_width_mult(0.5)
            .with_num_masks(8)
            .with_levels(levels)
            .with_c2psa(c2psa)
            .init(&ad);
        let x = Tensor::<4>::random([2, 3, 64, 96], Distribution::Default, &ad);
        for _ in 0..2 {
            let out = m.forward(x.clone());
            let _ = (out.cls_logits.sum() + out.proto.sum() + out.box_dist.sum()).backward();
        }
        m.valid()
    }

    fn opts(batch: usize, dynamic: bool) -> OnnxExportOptions {
        OnnxExportOptions {
            batch,
            dynamic,
            names: vec!["carcass".into(), "it's a \"part\"".into()],
            category_ids: vec![1, 7],
        }
    }

    fn input(b: usize, [h, w]: [usize; 2], seed: u64) -> Vec<f32> {
        // A deterministic pattern in [0, 1] (no RNG needed).
        (0..b * 3 * h * w)
            .map(|i| (((i as u64 * 2654435761 + seed) % 1000) as f32) / 999.0)
            .collect()
    }

    fn write(dir: &str, name: &str, model: &tract_onnx::pb::ModelProto) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("ct-onnx-{dir}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join(name);
        crate::util::write_atomic(&p, &encode(model)).unwrap();
        p
    }

    fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    /// chicktrain's forward in ultralytics' layout: (output0, its shape, proto, its shape).
    fn reference(
        m: &YoloSeg,
        x: &[f32],
        b: usize,
        hw: [usize; 2],
    ) -> (Vec<f32>, Vec<usize>, Vec<f32>, Vec<usize>) {
        let d = Device::flex();
        let t = Tensor::<4>::from_data(TensorData::new(x.to_vec(), [b, 3, hw[0], hw[1]]), &d);
        let out = m.forward(t);
        let (y0, s0) = ultralytics_output0(&out);
        let ps = out.proto.dims().to_vec();
        (y0, s0.to_vec(), to_host(out.proto), ps)
    }

    fn check_against_tract(levels: HeadLevels, c2psa: bool, tag: &str) {
        let m = small_model(levels, c2psa, 3);
        let hw = [64, 96];
        let model = export_yolo(&m, hw, &opts(2, false)).unwrap();
        let path = write(tag, "static.onnx", &model);
        let eng = TractEngine::load(&path, None).unwrap();
        let x = input(2, hw, 11);
        let (r0, s0, r1, s1) = reference(&m, &x, 2, hw);
        let out = eng.run(&[2, 3, hw[0], hw[1]], &x).unwrap();
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].shape, s0, "output0 shape");
        assert_eq!(out[1].shape, s1, "output1 shape");
        let (d0, d1) = (
            max_abs_diff(&out[0].data, &r0),
            max_abs_diff(&out[1].data, &r1),
        );
        eprintln!("{tag}: tract vs chicktrain max |Δ| output0 {d0:.3e}, output1 {d1:.3e}");
        assert!(
            d0 <= 1e-4 && d1 <= 1e-4,
            "{tag}: output0 {d0}, output1 {d1}"
        );
        // The comparison is not vacuous: boxes, scores and prototypes vary.
        let na = s0[2];
        assert!(
            r0[..na].iter().any(|&v| (v - r0[0]).abs() > 1.0),
            "box centres all equal"
        );
        assert!(r1.iter().any(|&v| (v - r1[0]).abs() > 1e-3));
    }

    #[test]
    fn tract_runs_export_like_chicktrain_p3p5_c2psa() {
        check_against_tract(HeadLevels::P3P5, true, "p3p5");
    }

    #[test]
    fn tract_runs_export_like_chicktrain_p4p5_no_c2psa() {
        check_against_tract(HeadLevels::P4P5, false, "p4p5");
    }

    #[test]
    fn dynamic_batch_matches_static() {
        let m = small_model(HeadLevels::P3P5, true, 5);
        let hw = [64, 64];
        let stat = write(
            "dyn",
            "static1.onnx",
            &export_yolo(&m, hw, &opts(1, false)).unwrap(),
        );
        let dynm = write(
            "dyn",
            "dynamic.onnx",
            &export_yolo(&m, hw, &opts(1, true)).unwrap(),
        );
        let es = TractEngine::load(&stat, None).unwrap();
        let ed = TractEngine::load(&dynm, None).unwrap();
        assert_eq!(ed.input_shape, vec![None, Some(3), Some(64), Some(64)]);
        assert_eq!(es.input_shape, vec![Some(1), Some(3), Some(64), Some(64)]);
        let x3 = input(3, hw, 2);
        let plane = 3 * 64 * 64;
        // One symbolic plan runs batch 1 and batch 3; each image equals the static run.
        let d3 = ed.run(&[3, 3, 64, 64], &x3).unwrap();
        let d1 = ed.run(&[1, 3, 64, 64], &x3[..plane]).unwrap();
        assert_eq!(d3[0].shape[0], 3);
        let (n0, n1) = (d3[0].data.len() / 3, d3[1].data.len() / 3);
        for i in 0..3 {
            let s = es
                .run(&[1, 3, 64, 64], &x3[i * plane..(i + 1) * plane])
                .unwrap();
            let a = max_abs_diff(&s[0].data, &d3[0].data[i * n0..(i + 1) * n0]);
            let b = max_abs_diff(&s[1].data, &d3[1].data[i * n1..(i + 1) * n1]);
            assert!(a <= 1e-4 && b <= 1e-4, "image {i}: {a} {b}");
        }
        assert!(max_abs_diff(&d1[0].data, &d3[0].data[..n0]) <= 1e-4);
        // And both agree with chicktrain.
        let (r0, _, r1, _) = reference(&m, &x3, 3, hw);
        assert!(max_abs_diff(&d3[0].data, &r0) <= 1e-4);
        assert!(max_abs_diff(&d3[1].data, &r1) <= 1e-4);
        // A static file refuses another batch with a message, not a panic.
        let e = es.run(&[3, 3, 64, 64], &x3).unwrap_err().to_string();
        assert!(e.contains("does not fit the declared"), "{e}");
    }

    #[test]
    fn metadata_reads_like_ultralytics() {
        let m = small_model(HeadLevels::P3P5, false, 1);
        let model = export_yolo(&m, [64, 64], &opts(4, true)).unwrap();
        let md = |k: &str| {
            crate::model::onnx::graph::metadata(&model, k)
                .unwrap()
                .to_string()
        };
        assert_eq!(md("task"), "segment");
        assert_eq!(md("stride"), "32");
        assert_eq!(md("imgsz"), "[64, 64]");
        assert_eq!(md("batch"), "4");
        assert_eq!(md("names"), r#"{0: 'carcass', 1: 'it\'s a "part"'}"#);
        assert_eq!(md("chicktrain_category_ids"), "[1, 7]");
        assert!(md("args").contains("'dynamic': True"));
        assert_eq!(model.opset_import[0].version, 17);
        let g = model.graph.as_ref().unwrap();
        let names: Vec<&str> = g.output.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["output0", "output1"]);
        assert_eq!(g.input[0].name, "images");
        // BatchNorm is folded: no BatchNormalization node survives.
        assert!(g.node.iter().all(|n| n.op_type != "BatchNormalization"));
    }

    #[test]
    fn bad_options_are_errors() {
        let m = small_model(HeadLevels::P4P5, false, 1);
        let mut o = opts(1, false);
        o.names.pop();
        let e = export_yolo(&m, [64, 64], &o).unwrap_err().to_string();
        assert!(
            e.contains("1 class names for a model with 2 classes"),
            "{e}"
        );
        let e = export_yolo(&m, [64, 70], &opts(1, false))
            .unwrap_err()
            .to_string();
        assert!(e.contains("multiples of 32"), "{e}");
        let e = export_yolo(&m, [64, 64], &opts(0, false))
            .unwrap_err()
            .to_string();
        assert!(e.contains("batch must be ≥ 1"), "{e}");
    }

    #[test]
    fn layout_postprocess_equals_raw_postprocess() {
        use crate::model::yolo::postprocess::{postprocess, postprocess_layout};
        let m = small_model(HeadLevels::P3P5, true, 9);
        let d = Device::flex();
        let x = input(2, [64, 96], 4);
        let out = m.forward(Tensor::<4>::from_data(
            TensorData::new(x, [2, 3, 64, 96]),
            &d,
        ));
        // conf 0: every anchor is a candidate, so NMS and masks see many boxes.
        let raw = postprocess(&out, 0.0, 0.7, 300);
        let (y0, s0) = ultralytics_output0(&out);
        let ps = out.proto.dims();
        let p = to_host(out.proto.clone());
        let lay = postprocess_layout((&y0, s0), (&p, ps), 2, [64, 96], (0.0, 0.7, 300));
        assert_eq!(raw.len(), lay.len());
        assert!(!raw[0].is_empty());
        for (a, b) in raw.iter().zip(&lay) {
            assert_eq!(a.len(), b.len());
            for (u, v) in a.iter().zip(b) {
                assert_eq!(u.class, v.class);
                assert!((u.score - v.score).abs() < 1e-6);
                for k in 0..4 {
                    assert!(
                        (u.bbox[k] - v.bbox[k]).abs() < 1e-3,
                        "{:?} vs {:?}",
                        u.bbox,
                        v.bbox
                    );
                }
                let (mu, mv) = (u.input_mask([64, 96]), v.input_mask([64, 96]));
                let diff = mu.iter().zip(&mv).filter(|(p, q)| p != q).count();
                assert!(diff <= 2, "{diff} mask pixels differ");
            }
        }
    }
}
