//! ONNX export of Mask R-CNN as three graphs: the parts of the network that are tensors
//! in, tensors out. What sits between them is data-dependent (anchors, proposal decoding
//! and NMS, RoIAlign with FPN level assignment, box decoding and NMS, mask pasting) and
//! stays in chicktrain's Rust: tract (the Rust runtime the tests and `predict --onnx` use)
//! has no `RoiAlign`, so a single two-stage graph would run in ONNX Runtime only.
//!
//! - backbone (`best.onnx`): `images` `[B, 3, H, W]` RGB in [0, 1] (ImageNet
//!   normalisation inside, as in the model) → `p2` … `p6` `[B, C, H/s, W/s]` (s = 4 … 64),
//!   and per level the RPN head's raw maps in torchvision's `RPNHead` layout,
//!   `rpn_objectness.pN` `[B, A, H/s, W/s]` and `rpn_deltas.pN` `[B, 4A, H/s, W/s]`
//!   (anchor-major: channel `4a + j` is delta j of anchor a);
//! - box head (`best.box_head.onnx`): `box_features` `[R, C, 7, 7]` (RoIAlign of the
//!   proposals) → `class_logits` `[R, nc + 1]` (background last) and `box_deltas`
//!   `[R, 4·nc]`;
//! - mask head (`best.mask_head.onnx`): `mask_features` `[R, C, 14, 14]` → `mask_logits`
//!   `[R, nc, 28, 28]`.
//!
//! `R` is the symbol `rois`; `B` is fixed or the symbol `batch`. Every BatchNorm is folded
//! into its conv (inference uses the running statistics). Opset 17.

use anyhow::{ensure, Result};
use burn::nn::BatchNorm;
use burn::tensor::{Device, Tensor, TensorData};
use tract_onnx::pb::ModelProto;

use super::resnet::{ConvBnRelu, ResBlock};
use super::{InferenceNet, MaskRcnn, PIXEL_MEAN, PIXEL_STD, STRIDES};
use crate::model::onnx::engine::{HostTensor, TractEngine};
use crate::model::onnx::graph::{Dim, GraphBuilder};
use crate::model::onnx::layers::{conv2d, conv_transpose2d, linear, symmetric_padding};
use crate::util::tensor::to_host;

/// The three graphs of an export.
pub struct MaskRcnnOnnx {
    pub backbone: ModelProto,
    pub box_head: ModelProto,
    pub mask_head: ModelProto,
}

/// Names of the FPN levels, finest first (the backbone graph's `pN` outputs).
pub const LEVELS: [&str; 5] = ["p2", "p3", "p4", "p5", "p6"];
/// Input and output names of the RoI head graphs.
pub const BOX_INPUT: &str = "box_features";
pub const BOX_OUTPUTS: [&str; 2] = ["class_logits", "box_deltas"];
pub const MASK_INPUT: &str = "mask_features";
pub const MASK_OUTPUT: &str = "mask_logits";

/// The backbone graph's outputs in order: `p2`…`p6`, then `rpn_objectness.p2`…,
/// then `rpn_deltas.p2`….
pub fn backbone_outputs() -> Vec<String> {
    let mut v: Vec<String> = LEVELS.iter().map(|s| s.to_string()).collect();
    v.extend(LEVELS.iter().map(|l| format!("rpn_objectness.{l}")));
    v.extend(LEVELS.iter().map(|l| format!("rpn_deltas.{l}")));
    v
}

/// A conv with its BatchNorm folded in (`w·γ/√(σ²+ε)`, `β − μ·γ/√(σ²+ε)`), then ReLU
/// if the layer has one.
fn conv_bn_relu(g: &mut GraphBuilder, scope: &str, x: &str, c: &ConvBnRelu) -> Result<String> {
    let conv = &c.conv;
    ensure!(
        conv.dilation == [1, 1] && conv.groups == 1,
        "{scope}: only undilated, ungrouped convs are exported"
    );
    let pad = symmetric_padding(conv, scope)?;
    let dims = conv.weight.dims();
    let (w, b) = fold(&to_host(conv.weight.val()), dims[0], &c.bn);
    let y = g.conv(
        &format!("{scope}/conv"),
        x,
        (&dims, &w),
        Some(&b),
        conv.stride,
        pad,
        1,
    );
    Ok(if c.act {
        g.relu(&format!("{scope}/relu"), &y)
    } else {
        y
    })
}

/// Folds `bn` into a bias-free conv weight of `c_out` filters.
fn fold(w: &[f32], c_out: usize, bn: &BatchNorm) -> (Vec<f32>, Vec<f32>) {
    let gamma = to_host(bn.gamma.val());
    let beta = to_host(bn.beta.val());
    let mean = to_host(bn.running_mean.value());
    let var = to_host(bn.running_var.value());
    let per = w.len() / c_out;
    let mut wf = Vec::with_capacity(w.len());
    let mut bf = Vec::with_capacity(c_out);
    for o in 0..c_out {
        let s = gamma[o] / (var[o] + bn.epsilon as f32).sqrt();
        wf.extend(w[o * per..(o + 1) * per].iter().map(|v| v * s));
        bf.push(beta[o] - mean[o] * s);
    }
    (wf, bf)
}

fn block(g: &mut GraphBuilder, scope: &str, x: &str, b: &ResBlock) -> Result<String> {
    let id = match &b.down {
        Some(d) => conv_bn_relu(g, &format!("{scope}/downsample"), x, d)?,
        None => x.to_string(),
    };
    let mut y = x.to_string();
    for (k, c) in b.convs.iter().enumerate() {
        y = conv_bn_relu(g, &format!("{scope}/conv{}", k + 1), &y, c)?;
    }
    let s = g.binary(scope, "Add", &y, &id);
    Ok(g.relu(&format!("{scope}/relu"), &s))
}

/// The three graphs of `model` at `input = [H, W]`; `batch` fixed, or `None` for the
/// symbol `batch`. `metadata` goes into each graph.
pub fn export_maskrcnn(
    model: &MaskRcnn,
    input: [usize; 2],
    batch: Option<usize>,
    metadata: &[(String, String)],
) -> Result<MaskRcnnOnnx> {
    let [h, w] = input;
    ensure!(
        h >= 64 && w >= 64 && h % 32 == 0 && w % 32 == 0,
        "ONNX export: input {h}×{w} must be multiples of 32 and ≥ 64"
    );
    ensure!(batch != Some(0), "ONNX export: batch must be ≥ 1");
    let bdim = match batch {
        Some(b) => Dim::Fixed(b),
        None => Dim::Named("batch".into()),
    };
    Ok(MaskRcnnOnnx {
        backbone: backbone_graph(model, [h, w], bdim, metadata)?,
        box_head: box_head_graph(model, metadata)?,
        mask_head: mask_head_graph(model, metadata)?,
    })
}

fn backbone_graph(
    model: &MaskRcnn,
    [h, w]: [usize; 2],
    bdim: Dim,
    metadata: &[(String, String)],
) -> Result<ModelProto> {
    let mut g = GraphBuilder::new();
    let x = g.input(
        "images",
        &[bdim.clone(), Dim::Fixed(3), Dim::Fixed(h), Dim::Fixed(w)],
    );
    // (x − mean) / std, as `MaskRcnn::features`.
    let mean = g.constant_f32("/normalize.mean", &[1, 3, 1, 1], &PIXEL_MEAN);
    let std = g.constant_f32("/normalize.std", &[1, 3, 1, 1], &PIXEL_STD);
    let y = g.binary("/normalize", "Sub", &x, &mean);
    let y = g.binary("/normalize", "Div", &y, &std);

    // ResNet (torchvision's names in the scopes: /body/layer1/0/conv1, …).
    let r = &model.backbone;
    let y = conv_bn_relu(&mut g, "/body/conv1", &y, &r.stem)?;
    let [k, _] = r.pool.kernel_size;
    let mut y = g.max_pool("/body/maxpool", &y, k, r.pool.stride[0], k / 2);
    let mut c = Vec::new();
    for (i, s) in r.stages.iter().enumerate() {
        for (j, b) in s.blocks.iter().enumerate() {
            y = block(&mut g, &format!("/body/layer{}/{j}", i + 1), &y, b)?;
        }
        c.push(y.clone());
    }

    // FPN, as `Fpn::forward`.
    let f = &model.fpn;
    let n = c.len();
    let mut p = vec![String::new(); n];
    let mut prev = conv2d(
        &mut g,
        &format!("/fpn/inner_blocks.{}", n - 1),
        &c[n - 1],
        &f.lateral[n - 1],
    )?;
    p[n - 1] = conv2d(
        &mut g,
        &format!("/fpn/layer_blocks.{}", n - 1),
        &prev,
        &f.output[n - 1],
    )?;
    for i in (0..n - 1).rev() {
        let lat = conv2d(
            &mut g,
            &format!("/fpn/inner_blocks.{i}"),
            &c[i],
            &f.lateral[i],
        )?;
        let up = g.upsample2x(&format!("/fpn/upsample.{i}"), &prev);
        prev = g.binary(&format!("/fpn/merge.{i}"), "Add", &lat, &up);
        p[i] = conv2d(
            &mut g,
            &format!("/fpn/layer_blocks.{i}"),
            &prev,
            &f.output[i],
        )?;
    }
    // P6: LastLevelMaxPool (1×1 max-pool, stride 2).
    let p6 = g.max_pool("/fpn/extra", &p[n - 1], 1, 2, 0);
    p.push(p6);

    // RPN head on every level (shared weights).
    let rpn = &model.rpn;
    let a = rpn.num_anchors;
    let mut objectness = Vec::new();
    let mut deltas = Vec::new();
    for (l, x) in p.iter().enumerate() {
        let sc = format!("/rpn/{}", LEVELS[l]);
        let t = conv2d(&mut g, &format!("{sc}/conv"), x, &rpn.conv)?;
        let t = g.relu(&format!("{sc}/relu"), &t);
        objectness.push(conv2d(
            &mut g,
            &format!("{sc}/cls_logits"),
            &t,
            &rpn.objectness,
        )?);
        deltas.push(conv2d(&mut g, &format!("{sc}/bbox_pred"), &t, &rpn.deltas)?);
    }
    let ch = f.channels;
    let names = backbone_outputs();
    let shapes = STRIDES.iter().map(|&s| (h.div_ceil(s), w.div_ceil(s)));
    let values = p.iter().chain(&objectness).chain(&deltas);
    for (k, (v, name)) in values.zip(&names).enumerate() {
        let (hl, wl) = shapes.clone().nth(k % 5).expect("five levels");
        let c = match k / 5 {
            0 => ch,
            1 => a,
            _ => 4 * a,
        };
        g.output(
            v,
            name,
            &[bdim.clone(), Dim::Fixed(c), Dim::Fixed(hl), Dim::Fixed(wl)],
        );
    }
    g.finish("chicktrain_maskrcnn_backbone", metadata)
}

fn box_head_graph(model: &MaskRcnn, metadata: &[(String, String)]) -> Result<ModelProto> {
    let cfg = &model.config;
    let p = cfg.roi.pool_size;
    let c = model.fpn.channels;
    let mut g = GraphBuilder::new();
    let r = Dim::Named("rois".into());
    let x = g.input(
        BOX_INPUT,
        &[r.clone(), Dim::Fixed(c), Dim::Fixed(p), Dim::Fixed(p)],
    );
    let bh = &model.box_head;
    let mut y = g.reshape("/box_head/flatten", &x, &[0, -1]);
    for (i, fc) in bh.fcs.iter().enumerate() {
        let sc = format!("/box_head/fc{}", i + 6);
        y = linear(&mut g, &sc, &y, fc)?;
        y = g.relu(&format!("{sc}/relu"), &y);
    }
    let cls = linear(&mut g, "/box_predictor/cls_score", &y, &bh.cls_score)?;
    let deltas = linear(&mut g, "/box_predictor/bbox_pred", &y, &bh.bbox_pred)?;
    let [_, k] = bh.cls_score.weight.dims();
    let [_, d] = bh.bbox_pred.weight.dims();
    g.output(&cls, BOX_OUTPUTS[0], &[r.clone(), Dim::Fixed(k)]);
    g.output(&deltas, BOX_OUTPUTS[1], &[r, Dim::Fixed(d)]);
    g.finish("chicktrain_maskrcnn_box_head", metadata)
}

fn mask_head_graph(model: &MaskRcnn, metadata: &[(String, String)]) -> Result<ModelProto> {
    let cfg = &model.config;
    let p = cfg.mask.pool_size;
    let c = model.fpn.channels;
    let mut g = GraphBuilder::new();
    let r = Dim::Named("rois".into());
    let x = g.input(
        MASK_INPUT,
        &[r.clone(), Dim::Fixed(c), Dim::Fixed(p), Dim::Fixed(p)],
    );
    let mh = &model.mask_head;
    let mut y = x;
    for (i, conv) in mh.convs.iter().enumerate() {
        let sc = format!("/mask_head/{i}");
        y = conv2d(&mut g, &sc, &y, conv)?;
        y = g.relu(&format!("{sc}/relu"), &y);
    }
    let y = conv_transpose2d(&mut g, "/mask_predictor/conv5_mask", &y, &mh.deconv)?;
    let y = g.relu("/mask_predictor/relu", &y);
    let y = conv2d(&mut g, "/mask_predictor/mask_fcn_logits", &y, &mh.predictor)?;
    let [k, ..] = mh.predictor.weight.dims();
    let m = p * mh.deconv.stride[0];
    g.output(
        &y,
        MASK_OUTPUT,
        &[r, Dim::Fixed(k), Dim::Fixed(m), Dim::Fixed(m)],
    );
    g.finish("chicktrain_maskrcnn_mask_head", metadata)
}

/// An export's three graphs run by tract: the [`InferenceNet`] of `predict --onnx`, so
/// the exported file goes through chicktrain's own proposal, RoIAlign, box and mask
/// postprocess ([`super::infer`]).
pub struct OnnxMaskRcnn {
    pub backbone: TractEngine,
    pub box_head: TractEngine,
    pub mask_head: TractEngine,
    pub device: Device,
}

fn to_tensor<const D: usize>(t: &HostTensor, dev: &Device) -> Result<Tensor<D>> {
    ensure!(
        t.shape.len() == D,
        "an ONNX output of shape {:?} where rank {D} is expected",
        t.shape
    );
    Ok(Tensor::from_data(
        TensorData::new(t.data.clone(), t.shape.clone()),
        dev,
    ))
}

fn run_graph(eng: &TractEngine, x: Tensor<4>, n_out: usize) -> Result<Vec<HostTensor>> {
    let shape = x.dims().to_vec();
    let out = eng.run(&shape, &to_host(x))?;
    ensure!(
        out.len() == n_out,
        "{}: {} outputs, a Mask R-CNN export has {n_out}",
        eng.path.display(),
        out.len()
    );
    Ok(out)
}

impl InferenceNet for OnnxMaskRcnn {
    fn features_and_rpn(
        &self,
        images: Tensor<4>,
    ) -> Result<(Vec<Tensor<4>>, Vec<(Tensor<4>, Tensor<4>)>)> {
        let out = run_graph(&self.backbone, images, 15)?;
        let t = |k: usize| to_tensor::<4>(&out[k], &self.device);
        let feats = (0..5).map(t).collect::<Result<Vec<_>>>()?;
        let maps = (0..5)
            .map(|l| Ok((t(5 + l)?, t(10 + l)?)))
            .collect::<Result<Vec<_>>>()?;
        Ok((feats, maps))
    }
    fn box_head(&self, pooled: Tensor<4>) -> Result<(Tensor<2>, Tensor<2>)> {
        let out = run_graph(&self.box_head, pooled, 2)?;
        Ok((
            to_tensor(&out[0], &self.device)?,
            to_tensor(&out[1], &self.device)?,
        ))
    }
    fn mask_head(&self, pooled: Tensor<4>) -> Result<Tensor<4>> {
        let out = run_graph(&self.mask_head, pooled, 1)?;
        to_tensor(&out[0], &self.device)
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::model::maskrcnn::mask_head::MaskHeadConfig;
    use crate::model::maskrcnn::roi_heads::RoiHeadsConfig;
    use crate::model::maskrcnn::MaskRcnnConfig;
    use crate::model::onnx::graph::encode;

    /// Largest |a − b| after checking the shapes agree.
    fn max_diff(what: &str, ours: Tensor<4>, onnx: &crate::model::onnx::engine::HostTensor) -> f32 {
        assert_eq!(ours.dims().to_vec(), onnx.shape, "{what}: shape");
        to_host(ours)
            .iter()
            .zip(&onnx.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max)
    }

    fn seeded(n: usize, seed: u32) -> Vec<f32> {
        // A small LCG: uniform [0, 1), no RNG crate needed for fixed test data.
        let mut s = seed as u64 * 6364136223846793005 + 1442695040888963407;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    }

    /// The three graphs through tract give chicktrain's own outputs within 1e-4 on a tiny
    /// two-class R18 (BatchNorm with non-trivial running statistics, so the folding is
    /// exercised), at a non-square input and batch 2.
    #[test]
    fn tract_runs_the_three_graphs_like_chicktrain() {
        let dev = Device::flex();
        let mut m = MaskRcnnConfig::new(18, 2)
            .with_width_mult(0.125)
            .with_fpn_channels(8)
            .with_input_size(64)
            .with_roi(RoiHeadsConfig {
                fc_dim: 16,
                ..RoiHeadsConfig::compact()
            })
            .with_mask(MaskHeadConfig {
                conv_dim: 8,
                num_conv: 2,
                ..MaskHeadConfig::compact()
            })
            .init(&dev);
        // Running statistics away from (0, 1): the fold must use them.
        let stem = &mut m.backbone.stem.bn;
        let c = stem.gamma.dims()[0];
        stem.running_mean = burn::module::RunningState::new(Tensor::from_data(
            TensorData::new(
                seeded(c, 1).iter().map(|v| v - 0.5).collect::<Vec<f32>>(),
                [c],
            ),
            &dev,
        ));
        stem.running_var = burn::module::RunningState::new(Tensor::from_data(
            TensorData::new(
                seeded(c, 2).iter().map(|v| v + 0.5).collect::<Vec<f32>>(),
                [c],
            ),
            &dev,
        ));
        let (b, h, w) = (2, 64, 96);
        let g = export_maskrcnn(&m, [h, w], Some(b), &[]).unwrap();
        let x = seeded(b * 3 * h * w, 3);
        let images: Tensor<4> = Tensor::from_data(TensorData::new(x.clone(), [b, 3, h, w]), &dev);
        let feats = m.features(images);
        let maps = m.rpn.forward_levels(&feats);

        let eng = TractEngine::from_bytes(&encode(&g.backbone), Path::new("backbone.onnx"), None)
            .unwrap();
        let out = eng.run(&[b, 3, h, w], &x).unwrap();
        assert_eq!(out.len(), 15);
        let mut worst = 0f32;
        for l in 0..5 {
            worst = worst.max(max_diff(LEVELS[l], feats[l].clone(), &out[l]));
            worst = worst.max(max_diff("objectness", maps[l].0.clone(), &out[5 + l]));
            worst = worst.max(max_diff("deltas", maps[l].1.clone(), &out[10 + l]));
        }
        eprintln!("backbone + FPN + RPN head: max |chicktrain − tract| = {worst:e}");
        assert!(worst <= 1e-4, "{worst}");

        let r = 3;
        let pooled = seeded(r * 8 * 7 * 7, 4);
        let (cls, deltas) = m.box_head.forward(Tensor::from_data(
            TensorData::new(pooled.clone(), [r, 8, 7, 7]),
            &dev,
        ));
        let eng =
            TractEngine::from_bytes(&encode(&g.box_head), Path::new("box.onnx"), None).unwrap();
        let out = eng.run(&[r, 8, 7, 7], &pooled).unwrap();
        assert_eq!(
            (out[0].shape.as_slice(), out[1].shape.as_slice()),
            (&[r, 3][..], &[r, 8][..])
        );
        let d_cls = max_diff(
            "class_logits",
            cls.reshape([r, 3, 1, 1]),
            &reshaped(&out[0], [r, 3, 1, 1]),
        );
        let d_box = max_diff(
            "box_deltas",
            deltas.reshape([r, 8, 1, 1]),
            &reshaped(&out[1], [r, 8, 1, 1]),
        );
        eprintln!("box head: class logits {d_cls:e}, deltas {d_box:e}");
        assert!(d_cls <= 1e-4 && d_box <= 1e-4);

        let mask_in = seeded(r * 8 * 14 * 14, 5);
        let logits = m.mask_head.forward(Tensor::from_data(
            TensorData::new(mask_in.clone(), [r, 8, 14, 14]),
            &dev,
        ));
        let eng =
            TractEngine::from_bytes(&encode(&g.mask_head), Path::new("mask.onnx"), None).unwrap();
        let out = eng.run(&[r, 8, 14, 14], &mask_in).unwrap();
        let d_mask = max_diff("mask_logits", logits, &out[0]);
        eprintln!("mask head: {d_mask:e}");
        assert!(d_mask <= 1e-4);
    }

    fn reshaped(
        t: &crate::model::onnx::engine::HostTensor,
        s: [usize; 4],
    ) -> crate::model::onnx::engine::HostTensor {
        assert_eq!(
            t.data.len(),
            s.iter().product::<usize>(),
            "{:?} vs {s:?}",
            t.shape
        );
        crate::model::onnx::engine::HostTensor {
            shape: s.to_vec(),
            data: t.data.clone(),
        }
    }

    #[test]
    fn bad_input_sizes_are_errors() {
        let m = MaskRcnnConfig::new(18, 1)
            .with_width_mult(0.125)
            .with_fpn_channels(8)
            .init(&Device::flex());
        let e = export_maskrcnn(&m, [100, 64], Some(1), &[]).err().unwrap();
        assert!(e.to_string().contains("100×64"), "{e}");
        assert!(export_maskrcnn(&m, [64, 64], Some(0), &[]).is_err());
    }
}
