//! Parity of chicktrain's YOLO-seg assigner and losses with ultralytics 8.4.190.
//!
//! The expected numbers in `tests/fixtures/yolo/*.json` were computed by
//! `tests/fixtures/yolo/make_fixtures.py` with ultralytics' own `bbox_iou(CIoU=True)`,
//! `TaskAlignedAssigner` and `v8SegmentationLoss` on the same inputs; these tests only read
//! the JSON.

use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::annotations::targets::{ImageTargets, Targets};
use chicktrain::model::yolo::assigner::{assign_image, ciou, AssignerConfig};
use chicktrain::model::yolo::loss::{ciou_tensor, yolo_loss, LossWeights};
use chicktrain::model::yolo::{AnchorGrid, YoloOutput};
use serde_json::Value;

mod common;

use common::json::floats;

fn load(name: &str) -> Value {
    common::json::fixture(&format!("yolo/{name}"))
}

fn box4(v: &Value) -> [f32; 4] {
    let f = floats(v);
    [f[0], f[1], f[2], f[3]]
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

#[test]
fn ciou_matches_ultralytics() {
    let f = load("ciou.json");
    let b1: Vec<[f32; 4]> = f["b1"].as_array().unwrap().iter().map(box4).collect();
    let b2: Vec<[f32; 4]> = f["b2"].as_array().unwrap().iter().map(box4).collect();
    let want = floats(&f["ciou"]);
    let dev = Device::flex();
    let t = |b: &Vec<[f32; 4]>| {
        let v: Vec<f32> = b.iter().flatten().copied().collect();
        Tensor::<2>::from_data(TensorData::new(v, [b.len(), 4]), &dev)
    };
    let got_t = ciou_tensor(t(&b1), t(&b2))
        .into_data()
        .try_into_vec::<f32>()
        .unwrap();
    for i in 0..want.len() {
        let got = ciou(b1[i], b2[i]);
        assert!(
            close(got, want[i], 1e-5),
            "pair {i}: host {got} vs ultralytics {}",
            want[i]
        );
        assert!(
            close(got_t[i], want[i], 1e-5),
            "pair {i}: tensor {} vs ultralytics {}",
            got_t[i],
            want[i]
        );
    }
}

#[test]
fn assigner_matches_ultralytics() {
    let f = load("assigner.json");
    let nc = f["num_classes"].as_u64().unwrap() as usize;
    let strides: Vec<usize> = f["strides"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let anchors: Vec<[f32; 2]> = f["anchors_px"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| {
            let p = floats(v);
            [p[0], p[1]]
        })
        .collect();
    let na = anchors.len();
    let cfg = AssignerConfig::for_strides(&strides);
    let mut total_fg = 0;
    for b in 0..2 {
        let scores = floats(&f["pd_scores"][b]);
        let boxes: Vec<[f32; 4]> = f["pd_boxes"][b]
            .as_array()
            .unwrap()
            .iter()
            .map(box4)
            .collect();
        let valid = f["gt_valid"][b].as_array().unwrap();
        // Padding rows (all zero) are passed too: the assigner must ignore them itself.
        let gt_boxes: Vec<[f32; 4]> = f["gt_boxes"][b]
            .as_array()
            .unwrap()
            .iter()
            .map(box4)
            .collect();
        let gt_labels: Vec<usize> = f["gt_labels"][b]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let a = assign_image(&cfg, &scores, &boxes, &anchors, &gt_boxes, &gt_labels, nc);
        let want_fg: Vec<bool> = f["fg"][b]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64() == Some(1))
            .collect();
        let want_gt: Vec<usize> = f["target_gt"][b]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let want_scores = floats(&f["target_scores"][b]);
        let want_boxes: Vec<[f32; 4]> = f["target_boxes"][b]
            .as_array()
            .unwrap()
            .iter()
            .map(box4)
            .collect();
        assert_eq!(valid.len(), gt_boxes.len());
        assert_eq!(a.fg, want_fg, "image {b}: foreground anchors");
        for i in 0..na {
            if want_fg[i] {
                assert_eq!(a.target_gt[i], want_gt[i], "image {b} anchor {i}");
                assert_eq!(a.target_boxes[i], want_boxes[i], "image {b} anchor {i}");
            }
        }
        for (i, (&g, &w)) in a.target_scores.iter().zip(&want_scores).enumerate() {
            assert!(close(g, w, 1e-5), "image {b} score {i}: {g} vs {w}");
        }
        total_fg += a.num_fg();
    }
    assert!(total_fg > 10, "fixture exercises positives ({total_fg})");
}

fn output_and_targets(case: &Value, dev: &Device) -> (YoloOutput, Targets) {
    let input = case["input"].as_u64().unwrap() as usize;
    let nc = case["num_classes"].as_u64().unwrap() as usize;
    let nm = case["num_masks"].as_u64().unwrap() as usize;
    let images = case["images"].as_array().unwrap();
    let b = images.len();
    let grid = AnchorGrid::new([input, input], &[8, 16, 32]);
    let na = grid.num_anchors();
    let ph = input / 4;
    let t3 =
        |v: &Value, c: usize| Tensor::<3>::from_data(TensorData::new(floats(v), [b, c, na]), dev);
    let out = YoloOutput {
        box_dist: t3(&case["box_dist"], 64),
        cls_logits: t3(&case["cls_logits"], nc),
        mask_coef: t3(&case["mask_coef"], nm),
        proto: Tensor::<4>::from_data(
            TensorData::new(floats(&case["proto"]), [b, nm, ph, ph]),
            dev,
        ),
        grid,
    };
    let mut targets = Targets::default();
    for img in images {
        let mut t = ImageTargets {
            boxes: img["boxes"].as_array().unwrap().iter().map(box4).collect(),
            classes: img["classes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap() as usize)
                .collect(),
            masks: Vec::new(),
        };
        for m in img["proto_masks"].as_array().unwrap() {
            // The fixture's masks are at prototype resolution; replicate each cell 4×4.
            let small = floats(m);
            let mut full = vec![0u8; input * input];
            for y in 0..input {
                for x in 0..input {
                    full[y * input + x] = u8::from(small[(y / 4) * ph + x / 4] > 0.5);
                }
            }
            t.masks.push(full);
        }
        targets.images.push(t);
    }
    (out, targets)
}

fn check_loss_case(name: &str, dev: &Device) {
    let f = load("loss.json");
    let case = &f[name];
    let (out, targets) = output_and_targets(case, dev);
    let l = yolo_loss(&out, &targets, &LossWeights::default());
    let [bx, cls, dfl, seg, total] = l.values();
    let want = |k: &str| case[k].as_f64().unwrap() as f32;
    eprintln!(
        "{name}: box {bx} cls {cls} dfl {dfl} seg {seg} total {total} ({} positives)",
        l.num_fg
    );
    for (what, got, exp) in [
        ("box", bx, want("box")),
        ("cls", cls, want("cls")),
        ("dfl", dfl, want("dfl")),
        ("seg", seg, want("seg")),
        ("total", total, want("total")),
    ] {
        assert!(
            close(got, exp, 1e-5),
            "{name}: {what} {got} vs ultralytics {exp}"
        );
    }
}

#[test]
fn loss_matches_ultralytics_with_gt() {
    check_loss_case("with_gt", &Device::flex());
}

#[test]
fn loss_matches_ultralytics_with_an_empty_image() {
    check_loss_case("one_empty_image", &Device::flex());
}

#[test]
fn loss_matches_ultralytics_all_empty() {
    check_loss_case("all_empty", &Device::flex());
}

#[test]
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn loss_matches_ultralytics_on_ndarray() {
    check_loss_case("with_gt", &Device::ndarray());
}

#[test]
fn parameter_counts_match_fixture() {
    let f = load("size.json");
    assert_eq!(f["ultralytics"], "8.4.190");
    use chicktrain::model::yolo::{Scale, YoloSegConfig};
    for (s, scale) in [("n", Scale::N), ("s", Scale::S)] {
        let want = f["params_nc1"][s].as_u64().unwrap() as usize;
        let got = YoloSegConfig::new(scale, 1)
            .init(&Device::flex())
            .summary(640)
            .params;
        // ultralytics also counts the 16 frozen DFL projection weights, which we keep as a
        // constant instead of a parameter.
        assert_eq!(got + 16, want, "scale {s}");
    }
}
