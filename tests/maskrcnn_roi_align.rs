//! RoIAlign parity with torchvision 0.29 `roi_align(aligned=True)` and a gradient check.
//!
//! `tests/fixtures/maskrcnn/roi_align.json` comes from
//! `tests/fixtures/maskrcnn/make_fixtures.py` (seeded random feature maps; RoIs that leave
//! the map, a zero-area RoI and one entirely outside; several scales, output sizes and
//! sampling ratios). This test only reads the JSON.

use burn::tensor::{Device, Distribution, Tensor, TensorData};
use chicktrain::model::maskrcnn::pooler::pool_levels;
use chicktrain::model::maskrcnn::roi_align::{roi_align, roi_align_host};
use chicktrain::util::tensor::to_host;
use serde_json::Value;

mod common;

use common::json::floats;

fn load() -> Value {
    common::json::fixture("maskrcnn/roi_align.json")
}

fn dims<const D: usize>(v: &Value) -> [usize; D] {
    let u: Vec<usize> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap() as usize)
        .collect();
    u.try_into().unwrap()
}

fn check_fixture(dev: &Device) {
    let f = load();
    let cases = f["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 5);
    for (ci, c) in cases.iter().enumerate() {
        let shape: [usize; 4] = dims(&c["input_shape"]);
        let input = floats(&c["input"]);
        let rois: Vec<(usize, [f32; 4])> = c["rois"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let r = floats(r);
                (r[0] as usize, [r[1], r[2], r[3], r[4]])
            })
            .collect();
        let scale = c["spatial_scale"].as_f64().unwrap() as f32;
        let out: [usize; 2] = dims(&c["output_size"]);
        let sr = c["sampling_ratio"].as_u64().unwrap() as usize;
        let want = floats(&c["output"]);
        let x = Tensor::<4>::from_data(TensorData::new(input.clone(), shape), dev);
        let got = roi_align(x, &rois, scale, out, sr);
        assert_eq!(
            got.dims().to_vec(),
            dims::<4>(&c["output_shape"]).to_vec(),
            "case {ci}"
        );
        let got = to_host(got);
        let mut worst = 0f32;
        for (g, w) in got.iter().zip(&want) {
            worst = worst.max((g - w).abs());
        }
        assert!(
            worst <= 1e-4,
            "case {ci}: max |diff| {worst} vs torchvision"
        );
        // The host version (used for mask targets) agrees as well.
        let [_, ch, h, w] = shape;
        let per = ch * out[0] * out[1];
        for (r, &(b, bx)) in rois.iter().enumerate() {
            let host = roi_align_host(
                &input[b * ch * h * w..(b + 1) * ch * h * w],
                [ch, h, w],
                bx,
                scale,
                out,
                sr,
            );
            for (g, w) in host.iter().zip(&want[r * per..(r + 1) * per]) {
                assert!((g - w).abs() <= 1e-4, "case {ci} RoI {r} host: {g} vs {w}");
            }
        }
        // Non-trivial: the fixture is not all zeros.
        assert!(
            want.iter().any(|v| v.abs() > 0.1),
            "case {ci} is degenerate"
        );
    }
}

#[test]
fn matches_torchvision_on_flex() {
    check_fixture(&Device::flex());
}

#[test]
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn matches_torchvision_on_ndarray() {
    check_fixture(&Device::ndarray());
}

/// `Σ out · r` for fixed random `r`: its gradient w.r.t. the features, against central
/// differences (RoIAlign is linear in the features, so differences are exact up to f32
/// rounding), on every element of a small map.
fn gradient_check(dev: Device) {
    let ad = dev.clone().autodiff();
    let shape = [2, 2, 6, 7];
    dev.seed(3);
    let x0: Tensor<4> = Tensor::random(shape, Distribution::Normal(0.0, 1.0), &dev);
    let xv = to_host(x0.clone());
    let rois = vec![
        (0, [1.0f32, 0.5, 5.5, 4.0]),
        (1, [-1.5, 2.0, 3.0, 7.5]),
        (1, [2.2, 1.1, 6.9, 5.3]),
        (0, [0.0, 0.0, 7.0, 6.0]),
    ];
    let out_hw = [3, 4];
    let r: Tensor<4> = Tensor::random([rois.len(), 2, 3, 4], Distribution::Normal(0.0, 1.0), &dev);
    let rv = to_host(r.clone());
    let f = |x: Vec<f32>| -> f64 {
        let t = Tensor::<4>::from_data(TensorData::new(x, shape), &dev);
        let o = to_host(roi_align(t, &rois, 1.0, out_hw, 2));
        o.iter().zip(&rv).map(|(a, b)| *a as f64 * *b as f64).sum()
    };
    let x = Tensor::<4>::from_data(TensorData::new(xv.clone(), shape), &ad).require_grad();
    let rr = Tensor::<4>::from_data(TensorData::new(rv.clone(), [rois.len(), 2, 3, 4]), &ad);
    let loss = (roi_align(x.clone(), &rois, 1.0, out_hw, 2) * rr).sum();
    let g = to_host(x.grad(&loss.backward()).expect("features get a gradient"));
    let eps = 0.05f32;
    let mut nonzero = 0;
    for i in 0..xv.len() {
        let mut p = xv.clone();
        p[i] += eps;
        let mut m = xv.clone();
        m[i] -= eps;
        let fd = ((f(p) - f(m)) / (2.0 * eps as f64)) as f32;
        assert!(
            (fd - g[i]).abs() <= 2e-3 * (1.0 + fd.abs()),
            "element {i}: autodiff {} vs finite difference {fd}",
            g[i]
        );
        nonzero += usize::from(g[i].abs() > 1e-3);
    }
    assert!(
        nonzero > xv.len() / 4,
        "only {nonzero} non-zero gradient entries"
    );
}

#[test]
fn gradient_matches_finite_differences_on_flex() {
    gradient_check(Device::flex());
}

#[test]
#[allow(deprecated)]
fn gradient_matches_finite_differences_on_ndarray() {
    gradient_check(Device::ndarray());
}

#[test]
fn pooler_gradient_reaches_the_assigned_level_only() {
    let ad = Device::flex().autodiff();
    let p2 = Tensor::<4>::ones([1, 2, 16, 16], &ad).require_grad();
    let p3 = Tensor::<4>::ones([1, 2, 8, 8], &ad).require_grad();
    // 20 px box → level 2.
    let out = pool_levels(
        &[p2.clone(), p3.clone()],
        2,
        &[(0, [4.0, 4.0, 24.0, 24.0])],
        7,
        2,
    );
    let grads = out.sum().backward();
    let g2 = to_host(p2.grad(&grads).unwrap());
    assert!(
        (g2.iter().sum::<f32>() - 2.0 * 49.0).abs() < 1e-3,
        "every output bin's weights sum to 1"
    );
    let g3 = p3.grad(&grads).map(to_host).unwrap_or_default();
    assert!(g3.iter().all(|v| *v == 0.0));
}
