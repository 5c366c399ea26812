//! Numerics at the extremes outside the YOLO loss (which `yolo_numerics.rs` covers):
//! BatchNorm on a batch of one and on constant input, the Mask R-CNN losses on
//! degenerate, huge, crowded, duplicated and mask-less targets and on saturated logits,
//! and IoU / NMS / box decoding with NaN, infinite and zero-size boxes. Every case must
//! give finite losses and gradients, or a defined (documented) result.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::model::detection::{box_iou, nms};
use chicktrain::model::maskrcnn::box_coder::{clip_box, BoxCoder};
use chicktrain::model::maskrcnn::losses::{bce_with_logits, cross_entropy, smooth_l1};
use chicktrain::model::maskrcnn::mask_head::mask_loss;
use chicktrain::model::maskrcnn::{ImageTargets, MaskRcnnConfig};
use chicktrain::model::yolo::blocks::ConvBn;
use chicktrain::model::yolo::postprocess::postprocess;
use chicktrain::model::yolo::{AnchorGrid, Scale, YoloOutput, YoloSegConfig};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

mod common;

#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn devices() -> [(&'static str, Device); 2] {
    [("flex", Device::flex()), ("ndarray", Device::ndarray())]
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data_as::<f32>().try_into_vec::<f32>().unwrap()
}

fn all_finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Conv-BN-SiLU in train mode (batch statistics) and eval mode (running statistics),
/// forward and backward, on one 1×1 image (each channel's batch variance is 0) and on a
/// constant batch: `(x − mean)/sqrt(var + eps)` must not divide by zero.
#[test]
fn batchnorm_with_batch_one_and_constant_input() {
    for (name, dev) in devices() {
        let ad = dev.clone().autodiff();
        dev.seed(3);
        let block = ConvBn::silu(3, 8, 3, 1, &ad);
        for (what, x) in [
            ("batch of one 1×1", vec![0.3f32, -2.0, 7.0]),
            ("constant 2×8×8", vec![0.5f32; 2 * 3 * 64]),
        ] {
            let shape = if x.len() == 3 {
                [1, 3, 1, 1]
            } else {
                [2, 3, 8, 8]
            };
            let x = Tensor::<4>::from_data(TensorData::new(x, shape), &ad).require_grad();
            let y = block.forward(x.clone());
            let out = values(y.clone());
            assert!(all_finite(&out), "{name} {what}: train-mode output {out:?}");
            let grads = y.powi_scalar(2).sum().backward();
            let gx = values(x.grad(&grads).expect("input gradient"));
            assert!(all_finite(&gx), "{name} {what}: input gradient");
            let gw = values(block.conv.weight.val().grad(&grads).expect("weight grad"));
            assert!(all_finite(&gw), "{name} {what}: weight gradient");
            let eval = block.valid();
            let xv = Tensor::<4>::from_data(x.into_data(), &dev);
            let ev = values(eval.forward(xv));
            assert!(all_finite(&ev), "{name} {what}: eval-mode output");
        }
        // A whole (tiny) YOLO-seg on one constant image: every BN in it sees zero variance
        // at the deepest levels, and at 32 px the SPPF runs on a 1×1 map (which panicked
        // in burn-ndarray's max pool before `Sppf::forward` special-cased it).
        let model = YoloSegConfig::new(Scale::N, 1)
            .with_input_size(32)
            .with_width_mult(0.5)
            .with_num_masks(4)
            .init(&ad);
        let x = Tensor::<4>::full([1, 3, 32, 32], 0.5, &ad);
        let out = model.forward(x);
        let loss = out.cls_logits.clone().sum() + out.proto.clone().sum() + out.box_dist.sum();
        let grads = loss.backward();
        let g = values(
            model.head.coef[0]
                .out
                .weight
                .val()
                .grad(&grads)
                .unwrap_or(Tensor::zeros([1, 1, 1, 1], &dev)),
        );
        assert!(all_finite(&g), "{name}: YOLO gradient");
        let eval = model.valid();
        let e = eval.forward(Tensor::<4>::full([1, 3, 32, 32], 0.5, &dev));
        assert!(
            all_finite(&values(e.cls_logits)),
            "{name}: YOLO eval logits"
        );
    }
}

const SIZE: usize = 64;

fn tiny_maskrcnn() -> MaskRcnnConfig {
    common::tiny::tiny_maskrcnn(
        SIZE,
        common::tiny::TinyWidths {
            fpn: 16,
            fc: 32,
            mask_conv: 16,
            mask_convs: 1,
        },
    )
}

fn mask_of(b: [f32; 4]) -> Vec<u8> {
    let mut m = vec![0u8; SIZE * SIZE];
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (xf, yf) = (x as f32 + 0.5, y as f32 + 0.5);
            if xf >= b[0] && xf < b[2] && yf >= b[1] && yf < b[3] {
                m[y * SIZE + x] = 1;
            }
        }
    }
    m
}

fn targets(boxes: &[[f32; 4]], empty_masks: bool) -> ImageTargets {
    ImageTargets {
        boxes: boxes.to_vec(),
        classes: vec![0; boxes.len()],
        masks: boxes
            .iter()
            .map(|&b| {
                if empty_masks {
                    vec![0; SIZE * SIZE]
                } else {
                    mask_of(b)
                }
            })
            .collect(),
    }
}

/// The target extremes through every Mask R-CNN loss, forward and backward.
#[test]
fn maskrcnn_losses_stay_finite_on_extreme_targets() {
    let crowd: Vec<[f32; 4]> = (0..200)
        .map(|i| {
            let (x, y) = ((i % 20) as f32 * 3.0, (i / 20) as f32 * 6.0);
            [x, y, x + 4.0 + (i % 7) as f32, y + 5.0]
        })
        .collect();
    let cases: Vec<(&str, Vec<ImageTargets>)> = vec![
        (
            "zero width, zero height, zero area",
            vec![
                targets(&[[10.0, 10.0, 10.0, 40.0], [5.0, 20.0, 50.0, 20.0]], false),
                targets(&[[30.0, 30.0, 30.0, 30.0], [8.0, 8.0, 30.0, 30.0]], false),
            ],
        ),
        (
            "boxes of 1e4 px",
            vec![
                targets(&[[-5000.0, -5000.0, 5000.0, 5000.0]], false),
                targets(&[[0.0, 0.0, 1e4, 20.0], [10.0, 10.0, 20.0, 20.0]], false),
            ],
        ),
        ("200 GT", vec![targets(&crowd, false), targets(&[], false)]),
        (
            "identical duplicates",
            vec![
                targets(&[[12.0, 12.0, 40.0, 44.0]; 5], false),
                targets(&[[1.0, 2.0, 30.0, 20.0]; 2], false),
            ],
        ),
        (
            "empty masks",
            vec![
                targets(&[[12.0, 12.0, 40.0, 44.0]], true),
                targets(&[[1.0, 2.0, 30.0, 20.0]], true),
            ],
        ),
        (
            "all images empty",
            vec![targets(&[], false), targets(&[], false)],
        ),
    ];
    let dev = Device::flex();
    dev.seed(1);
    let ad = dev.autodiff();
    let model = tiny_maskrcnn().init(&ad);
    for (what, t) in cases {
        let x = Tensor::<4>::full([2, 3, SIZE, SIZE], 0.4, &ad);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let l = model.forward_train(x, &t, &mut rng);
        let v = l.values();
        assert!(all_finite(&v), "{what}: loss terms {v:?}");
        let grads = l.total.backward();
        let rpn = model.rpn.conv.weight.val().grad(&grads).map(values);
        let head = model
            .box_head
            .cls_score
            .weight
            .val()
            .grad(&grads)
            .map(values);
        for (name, g) in [("rpn", rpn), ("box head", head)] {
            if let Some(g) = g {
                assert!(all_finite(&g), "{what}: {name} gradient");
            }
        }
    }
}

/// Saturated logits (±1e4) and huge deltas through the loss primitives.
#[test]
fn maskrcnn_loss_primitives_with_saturated_inputs() {
    let ad = Device::flex().autodiff();
    let leaf = |v: Vec<f32>, s: [usize; 2]| {
        Tensor::<2>::from_data(TensorData::new(v, s), &ad).require_grad()
    };
    // Cross-entropy: confident and wrong, confident and right.
    let logits = leaf(vec![1e4, -1e4, -1e4, 1e4, 0.0, 1e4], [2, 3]);
    let ce = cross_entropy(logits.clone(), &[1, 2]);
    let g = ce.clone().backward();
    assert!(all_finite(&values(ce)));
    assert!(all_finite(&values(logits.grad(&g).unwrap())));
    // BCE (RPN objectness, masks).
    let x = leaf(vec![1e4, -1e4, 1e4, -1e4], [2, 2]);
    let t = Tensor::<2>::from_data(TensorData::new(vec![0.0f32, 1.0, 1.0, 0.0], [2, 2]), &ad);
    let b = bce_with_logits(x.clone(), t).sum();
    let g = b.clone().backward();
    let bv = values(b);
    assert!(all_finite(&bv) && bv[0] > 1e4, "{bv:?}");
    assert!(all_finite(&values(x.grad(&g).unwrap())));
    // Smooth-L1 on deltas of 1e4 and a target of -1e4.
    let d = leaf(vec![1e4, -1e4, 0.0, 3.0], [1, 4]);
    let tgt = Tensor::<2>::from_data(TensorData::new(vec![-1e4f32, 0.0, 0.0, 3.0], [1, 4]), &ad);
    let s = smooth_l1(d.clone(), tgt, 1.0 / 9.0).sum();
    let g = s.clone().backward();
    assert!(all_finite(&values(s)));
    assert!(all_finite(&values(d.grad(&g).unwrap())));
    // Mask loss: ±1e4 logits, all-empty and all-full targets, and no masks at all.
    let m = 4;
    let ml = Tensor::<4>::from_data(
        TensorData::new(
            (0..2 * m * m)
                .map(|i| if i % 2 == 0 { 1e4 } else { -1e4 })
                .collect::<Vec<f32>>(),
            [2, 1, m, m],
        ),
        &ad,
    )
    .require_grad();
    let mut tg = vec![0f32; m * m];
    tg.extend(vec![1f32; m * m]);
    let l = mask_loss(ml.clone(), &[0, 0], tg);
    let g = l.clone().backward();
    assert!(all_finite(&values(l)));
    assert!(all_finite(&values(ml.grad(&g).unwrap())));
    let none = mask_loss(Tensor::<4>::zeros([0, 1, m, m], &ad), &[], vec![]);
    assert_eq!(values(none), vec![0.0]);
}

/// `box_iou` is in [0, 1] for any input: non-finite or zero-area pairs give 0.
#[test]
fn iou_of_degenerate_and_non_finite_boxes_is_defined() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let good = [0.0, 0.0, 10.0, 10.0];
    for b in [
        [nan, 0.0, 10.0, 10.0],
        [0.0, 0.0, inf, 10.0],
        [-inf, -inf, inf, inf],
        [5.0, 5.0, 5.0, 5.0],
        [5.0, 0.0, 5.0, 10.0],
        [10.0, 10.0, 0.0, 0.0], // inverted
    ] {
        for (x, y) in [(good, b), (b, good), (b, b)] {
            let v = box_iou(x, y);
            assert!((0.0..=1.0).contains(&v), "{x:?} {y:?}: {v}");
        }
    }
    assert_eq!(box_iou(good, good), 1.0);
}

/// NMS never keeps a candidate with a NaN score or a non-finite box (they come from a
/// diverged model and would reach results.json as `null`), keeps zero-area boxes apart
/// (IoU 0), collapses identical duplicates to the first, and honours `max_det`, 0
/// included.
#[test]
fn nms_with_nan_inf_zero_area_and_duplicates() {
    let nan = f32::NAN;
    let b = [0.0, 0.0, 10.0, 10.0];
    let cands = vec![
        (b, nan, 0),                                // 0: NaN score
        ([nan, 0.0, 10.0, 10.0], 0.99, 0),          // 1: NaN box
        ([0.0, 0.0, f32::INFINITY, 10.0], 0.98, 0), // 2: infinite box
        (b, 0.9, 0),                                // 3
        (b, 0.9, 0),                                // 4: duplicate of 3
        ([3.0, 3.0, 3.0, 3.0], 0.8, 0),             // 5: zero area
        ([3.0, 3.0, 3.0, 3.0], 0.7, 0),             // 6: zero area duplicate (IoU 0 → kept)
        (b, 0.6, 1),                                // 7: other class
        (b, f32::INFINITY, 0),                      // 8: +inf score: ranks first, suppresses 3, 4
        (b, f32::NEG_INFINITY, 2),                  // 9: −inf score: last, still a score
    ];
    let keep = nms(&cands, 0.5, 100);
    assert_eq!(keep, vec![8, 5, 6, 7, 9]);
    assert_eq!(nms(&cands, 0.5, 2), vec![8, 5]);
    assert!(nms(&cands, 0.5, 0).is_empty());
    assert!(nms(&[], 0.5, 10).is_empty());
}

/// Box decoding: `dw`, `dh` are clamped (+inf and NaN too), so a box never grows past
/// exp(scale_clamp) = 62.5× its anchor; non-finite `dx`, `dy` or a −inf `dw` give boxes
/// that the proposal and detection filters (finite, positive size after clipping) drop.
#[test]
fn box_decoding_with_non_finite_deltas() {
    let c = BoxCoder::rpn();
    let anchor = [10.0, 10.0, 26.0, 26.0];
    let kept = |b: [f32; 4]| b.iter().all(|v| v.is_finite()) && b[2] > b[0] && b[3] > b[1];
    let inf = f32::INFINITY;
    for d in [
        [0.0, 0.0, inf, inf],
        [0.0, 0.0, f32::NAN, f32::NAN],
        [0.0, 0.0, 1e30, 1e30],
    ] {
        let b = c.decode(d, anchor);
        assert!(kept(b), "{d:?} → {b:?}");
        assert!((b[2] - b[0] - 1000.0).abs() < 0.1, "{d:?} → {b:?}");
    }
    for d in [
        [f32::NAN, 0.0, 0.0, 0.0],
        [inf, 0.0, 0.0, 0.0],
        [0.0, -inf, 0.0, 0.0],
        [0.0, 0.0, -inf, 0.0],
    ] {
        let b = clip_box(c.decode(d, anchor), [64, 64]);
        assert!(!kept(b), "{d:?} → {b:?} should be dropped");
    }
}

/// YOLO postprocess on NaN, ±inf and ±1e4 outputs: no panic, and every detection it
/// returns has finite coordinates and score.
#[test]
fn yolo_postprocess_with_non_finite_outputs() {
    let dev = Device::flex();
    let grid = AnchorGrid::new([64, 64], &[8, 16, 32]);
    let na = grid.num_anchors();
    for (what, fill) in [
        ("NaN", f32::NAN),
        ("+inf", f32::INFINITY),
        ("-inf", f32::NEG_INFINITY),
        ("1e4", 1e4),
        ("-1e4", -1e4),
    ] {
        let t3 = |c: usize, v: f32| {
            Tensor::<3>::from_data(TensorData::new(vec![v; c * na], [1, c, na]), &dev)
        };
        // Mixed: boxes from `fill`, class logits high so candidates pass the threshold.
        let out = YoloOutput {
            box_dist: t3(64, fill),
            cls_logits: t3(1, if fill.is_nan() { fill } else { 5.0 }),
            mask_coef: t3(4, fill),
            proto: Tensor::<4>::from_data(
                TensorData::new(vec![fill; 4 * 16 * 16], [1, 4, 16, 16]),
                &dev,
            ),
            grid: grid.clone(),
        };
        let dets = postprocess(&out, 0.25, 0.7, 300);
        for d in &dets[0] {
            assert!(
                d.bbox.iter().all(|v| v.is_finite()) && d.score.is_finite(),
                "{what}: {d:?}"
            );
        }
    }
}
