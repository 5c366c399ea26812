//! The YOLO-seg losses stay finite, with finite gradients, on the inputs that produce NaN
//! in the reference implementation: empty images, an all-empty batch, zero-width /
//! zero-height / zero-area boxes, and saturated logits (±1e4) in every head output.

use burn::tensor::{Device, Distribution, Tensor};
use chicktrain::annotations::targets::{ImageTargets, Targets};
use chicktrain::model::yolo::loss::{yolo_loss, LossWeights};
use chicktrain::model::yolo::{AnchorGrid, YoloOutput};

const IMG: usize = 64;
const NM: usize = 4;

/// Leaves on an autodiff device, filled by `fill` (values in standard units).
fn leaves(dev: &Device, b: usize, fill: &dyn Fn([usize; 4]) -> Tensor<4>) -> [Tensor<4>; 4] {
    let grid = AnchorGrid::new([IMG, IMG], &[8, 16, 32]);
    let na = grid.num_anchors();
    [
        fill([b, 64, na, 1]),
        fill([b, 1, na, 1]),
        fill([b, NM, na, 1]),
        fill([b, NM, IMG / 4, IMG / 4]),
    ]
    .map(|t| Tensor::<4>::from_data(t.into_data(), dev).require_grad())
}

fn output(l: &[Tensor<4>; 4]) -> YoloOutput {
    YoloOutput {
        box_dist: l[0].clone().squeeze_dim(3),
        cls_logits: l[1].clone().squeeze_dim(3),
        mask_coef: l[2].clone().squeeze_dim(3),
        proto: l[3].clone(),
        grid: AnchorGrid::new([IMG, IMG], &[8, 16, 32]),
    }
}

fn mask_of(b: [f32; 4]) -> Vec<u8> {
    let mut m = vec![0u8; IMG * IMG];
    for y in 0..IMG {
        for x in 0..IMG {
            let (xf, yf) = (x as f32, y as f32);
            if xf >= b[0] && xf < b[2] && yf >= b[1] && yf < b[3] {
                m[y * IMG + x] = 1;
            }
        }
    }
    m
}

fn image(boxes: &[[f32; 4]]) -> ImageTargets {
    ImageTargets {
        boxes: boxes.to_vec(),
        classes: vec![0; boxes.len()],
        masks: boxes.iter().map(|&b| mask_of(b)).collect(),
    }
}

fn assert_finite(
    dev: &Device,
    targets: &Targets,
    fill: &dyn Fn([usize; 4]) -> Tensor<4>,
    what: &str,
) -> usize {
    let l = leaves(dev, targets.images.len(), fill);
    let loss = yolo_loss(&output(&l), targets, &LossWeights::default());
    let v = loss.values();
    assert!(v.iter().all(|x| x.is_finite()), "{what}: loss terms {v:?}");
    let grads = loss.total.backward();
    // Class logits always receive a gradient; the other outputs do when there are positives.
    let needed = if loss.num_fg > 0 { 4 } else { 1 };
    for (i, leaf) in l.iter().enumerate() {
        let order = [1, 0, 2, 3][..needed].contains(&i);
        match leaf.grad(&grads) {
            Some(g) => {
                let g = g.into_data().try_into_vec::<f32>().unwrap();
                assert!(
                    g.iter().all(|x| x.is_finite()),
                    "{what}: gradient of output {i} not finite"
                );
            }
            None => assert!(!order, "{what}: output {i} got no gradient"),
        }
    }
    loss.num_fg
}

fn normal(s: [usize; 4]) -> Tensor<4> {
    Tensor::random(s, Distribution::Normal(0.0, 1.0), &Device::flex())
}

/// Alternating ±1e4 (saturates softmax, sigmoid and BCE).
fn saturated(s: [usize; 4]) -> Tensor<4> {
    let n: usize = s.iter().product();
    let v: Vec<f32> = (0..n)
        .map(|i| if i % 3 == 0 { 1e4 } else { -1e4 })
        .collect();
    Tensor::from_data(burn::tensor::TensorData::new(v, s), &Device::flex())
}

fn degenerate_batch() -> Targets {
    Targets {
        images: vec![
            image(&[[10.0, 10.0, 40.0, 30.0], [20.0, 5.0, 20.0, 35.0]]), // zero width
            image(&[[5.0, 40.0, 50.0, 40.0]]),                           // zero height
            image(&[[30.0, 30.0, 30.0, 30.0], [0.0, 0.0, 64.0, 64.0]]),  // zero area + full image
            image(&[]),                                                  // empty
        ],
    }
}

#[test]
fn finite_with_degenerate_boxes_and_empty_images() {
    let dev = Device::flex().autodiff();
    let fg = assert_finite(&dev, &degenerate_batch(), &normal, "normal logits");
    assert!(fg > 0, "degenerate batch still has positives");
}

#[test]
fn finite_with_saturated_logits() {
    let dev = Device::flex().autodiff();
    let fg = assert_finite(&dev, &degenerate_batch(), &saturated, "±1e4 logits");
    assert!(fg > 0);
}

#[test]
fn all_empty_batch_has_only_a_class_loss() {
    let dev = Device::flex().autodiff();
    let t = Targets {
        images: vec![image(&[]), image(&[])],
    };
    assert_eq!(assert_finite(&dev, &t, &saturated, "all-empty ±1e4"), 0);
    let l = leaves(&dev, 2, &normal);
    let v = yolo_loss(&output(&l), &t, &LossWeights::default()).values();
    assert_eq!(
        [v[0], v[2], v[3]],
        [0.0, 0.0, 0.0],
        "box, dfl, seg without positives: {v:?}"
    );
    assert!(v[1] > 0.0);
}

#[test]
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn finite_on_ndarray() {
    let dev = Device::ndarray().autodiff();
    assert_finite(&dev, &degenerate_batch(), &saturated, "ndarray ±1e4");
}

#[test]
fn p4_p5_model_without_attention_trains_a_step() {
    // Heads on strides 16 and 32 only (prototypes at 1/8), no C2PSA: the assigner's minimum
    // GT side becomes 32 px and the mask loss runs at the coarser prototype grid.
    use burn::tensor::TensorData;
    use chicktrain::data::ellipses::ellipse_batch;
    use chicktrain::model::yolo::{HeadLevels, Scale, YoloSegConfig};
    let dev = Device::flex().autodiff();
    dev.seed(5);
    let model = YoloSegConfig::new(Scale::N, 1)
        .with_input_size(64)
        .with_width_mult(0.5)
        .with_levels(HeadLevels::P4P5)
        .with_c2psa(false)
        .init(&dev);
    let (px, targets) = ellipse_batch(2, 64, 3, 9);
    let x = Tensor::<4>::from_data(TensorData::new(px, [2, 3, 64, 64]), &dev);
    let out = model.forward(x);
    assert_eq!(out.proto.dims()[2..], [8, 8]);
    let loss = yolo_loss(&out, &targets, &LossWeights::default());
    let v = loss.values();
    assert!(loss.num_fg > 0 && v.iter().all(|x| x.is_finite()), "{v:?}");
    assert!(v[3] > 0.0, "mask loss present: {v:?}");
    let grads = loss.total.backward();
    let g = model.head.coef[0]
        .out
        .weight
        .val()
        .grad(&grads)
        .expect("coef head gradient");
    let g = g.into_data().try_into_vec::<f32>().unwrap();
    assert!(g.iter().all(|x| x.is_finite()) && g.iter().any(|&x| x != 0.0));
}

/// The other extremes of the issue: boxes of 1e4 px (far larger than the image), 200 GT
/// in one image, identical duplicate boxes, and instances whose mask is empty (a box
/// without pixels, e.g. a sliver cut away by the crop).
#[test]
fn finite_with_huge_crowded_duplicate_and_maskless_targets() {
    let dev = Device::flex().autodiff();
    let crowd: Vec<[f32; 4]> = (0..200)
        .map(|i| {
            let (x, y) = ((i % 20) as f32 * 3.0, (i / 20) as f32 * 6.0);
            [x, y, x + 4.0 + (i % 7) as f32, y + 5.0]
        })
        .collect();
    let mut maskless = image(&[[8.0, 8.0, 40.0, 40.0], [20.0, 30.0, 60.0, 50.0]]);
    maskless.masks.iter_mut().for_each(|m| m.fill(0));
    let t = Targets {
        images: vec![
            image(&[[-5000.0, -5000.0, 5000.0, 5000.0], [0.0, 0.0, 1e4, 30.0]]),
            image(&crowd),
            image(&[[12.0, 12.0, 40.0, 44.0]; 6]),
            maskless,
        ],
    };
    for (what, fill) in [
        ("normal", &normal as &dyn Fn([usize; 4]) -> Tensor<4>),
        ("±1e4", &saturated),
    ] {
        let fg = assert_finite(&dev, &t, fill, what);
        assert!(fg > 0, "{what}: positives assigned");
    }
}
