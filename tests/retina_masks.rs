//! Masks at the original image size, against the reference tools:
//! ultralytics 8.4.190 `process_mask_native` (`retina_masks=True`) and `scale_boxes` for
//! YOLO-seg, detectron2's `paste_masks_in_image` pixel model (through torch's
//! `grid_sample`) for Mask R-CNN, and torchvision 0.29's `paste_masks_in_image` as a
//! looser cross-check. Then the same decoding through `to_coco`, the path eval and
//! predict take.
//!
//! `tests/fixtures/masks/retina.json` comes from `tests/fixtures/masks/make_fixtures.py`
//! (seeded random prototypes, coefficients, mask probabilities and boxes; a square image
//! and non-square ones whose letterbox padding makes ultralytics pre-upsample the
//! prototypes by 1, 2 and 4). This test only reads the JSON.

use std::sync::Arc;

use chicktrain::annotations::mask::Mask;
use chicktrain::annotations::rle::Rle;
use chicktrain::data::letterbox::Letterbox;
use chicktrain::infer::validate::to_coco;
use chicktrain::model::detection::Detection;
use chicktrain::model::instance_mask::{paste_roi_mask, prototype_mask, MaskSource, Prototypes};
use serde_json::Value;

mod common;

use common::json::floats;

fn load() -> Value {
    common::json::fixture("masks/retina.json")
}

fn ints(v: &Value) -> Vec<u32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap() as u32)
        .collect()
}

/// xyxy boxes, stored flat or as a list of lists.
fn boxes(v: &Value) -> Vec<[f32; 4]> {
    let flat: Vec<f32> = v
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|b| {
            if b.is_array() {
                floats(b)
            } else {
                floats(&Value::Array(vec![b.clone()]))
            }
        })
        .collect();
    flat.chunks(4).map(|b| b.try_into().unwrap()).collect()
}

/// The reference mask of a `w × h` image from its column-major runs.
fn from_runs(v: &Value, (w, h): (u32, u32)) -> Mask {
    Rle::from_counts(h, w, ints(v)).unwrap().decode()
}

fn differing(a: &Mask, b: &Mask) -> usize {
    a.data
        .iter()
        .zip(&b.data)
        .filter(|(x, y)| (**x != 0) != (**y != 0))
        .count()
}

struct YoloCase {
    orig: (u32, u32),
    input: u32,
    protos: Arc<Prototypes>,
    coefs: Vec<Vec<f32>>,
    boxes_input: Vec<[f32; 4]>,
    boxes_orig: Vec<[f32; 4]>,
    case: Value,
}

fn yolo_cases() -> Vec<YoloCase> {
    let doc = load();
    doc["yolo"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let o = ints(&c["orig"]);
            let s = ints(&c["proto_shape"]);
            let (nm, mh, mw) = (s[0] as usize, s[1] as usize, s[2] as usize);
            let input = c["input"].as_u64().unwrap() as u32;
            let coefs = floats(&c["coefs"]).chunks(nm).map(|x| x.to_vec()).collect();
            YoloCase {
                orig: (o[0], o[1]),
                input,
                protos: Arc::new(Prototypes {
                    data: floats(&c["protos"]),
                    channels: nm,
                    height: mh,
                    width: mw,
                    stride: input as usize / mh,
                }),
                coefs,
                boxes_input: boxes(&c["boxes_input"]),
                boxes_orig: boxes(&c["boxes_orig"]),
                case: c.clone(),
            }
        })
        .collect()
}

#[test]
fn yolo_masks_match_ultralytics_process_mask_native() {
    let cases = yolo_cases();
    assert_eq!(cases.len(), 5);
    let mut checked = 0;
    for c in &cases {
        let lb = Letterbox::new(c.orig, c.input);
        for (k, coef) in c.coefs.iter().enumerate() {
            // Boxes: Letterbox::unbox_xyxy is ultralytics' scale_boxes (f64 here, f32 there).
            let b = lb.unbox_xyxy(c.boxes_input[k].map(|v| v as f64));
            for (got, want) in b.iter().zip(c.boxes_orig[k]) {
                assert!(
                    (got - want as f64).abs() < 1e-3,
                    "{:?}: box {k}: {b:?} vs {:?}",
                    c.orig,
                    c.boxes_orig[k]
                );
            }
            let want = from_runs(&c.case["native_runs"][k], c.orig);
            let got = prototype_mask(coef, &c.protos, c.orig, c.boxes_orig[k]);
            assert!(got.window.width <= c.orig.0 && got.window.height <= c.orig.1);
            let got = got.full();
            assert_eq!(
                differing(&got, &want),
                0,
                "{:?} detection {k}: {} of {} reference pixels",
                c.orig,
                got.area(),
                want.area()
            );
            // At the input size: process_mask(..., upsample=True).
            let want = from_runs(&c.case["input_runs"][k], (c.input, c.input));
            let got = prototype_mask(coef, &c.protos, (c.input, c.input), c.boxes_input[k]).full();
            assert_eq!(
                differing(&got, &want),
                0,
                "{:?} detection {k} at the input",
                c.orig
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 25);
}

#[test]
fn maskrcnn_masks_match_detectron2_paste_and_stay_close_to_torchvision() {
    let doc = load();
    let mut checked = 0;
    for c in doc["maskrcnn"].as_array().unwrap() {
        let o = ints(&c["orig"]);
        let orig = (o[0], o[1]);
        let m = c["mask_size"].as_u64().unwrap() as usize;
        let probs = floats(&c["probs"]);
        for (k, bx) in boxes(&c["boxes"]).into_iter().enumerate() {
            let p = &probs[k * m * m..(k + 1) * m * m];
            let got = paste_roi_mask(p, m, bx, orig, 0.5).full();
            let want = from_runs(&c["detectron2_runs"][k], orig);
            assert_eq!(differing(&got, &want), 0, "{orig:?} mask {k}: {bx:?}");
            // torchvision rounds the box to whole pixels and pads the map by one cell: the
            // same mask up to about a pixel along the mask's outline, which stays inside
            // the box, so at most a band of one box perimeter differs.
            let tv = from_runs(&c["torchvision_runs"][k], orig);
            let band = 2.0 * ((bx[2] - bx[0]) + (bx[3] - bx[1]));
            let d = differing(&got, &tv);
            assert!(
                (d as f32) <= band,
                "{orig:?} mask {k}: {d} pixels differ from torchvision (band {band})"
            );
            assert!(got.area() > 0);
            checked += 1;
        }
    }
    assert_eq!(checked, 10);
}

#[test]
fn to_coco_decodes_at_the_original_size() {
    // Through the eval path: a detection at the input, its box and mask mapped to the
    // original image, the RLE built from the box window.
    for c in yolo_cases() {
        for (k, coef) in c.coefs.iter().enumerate() {
            let b = c.boxes_input[k];
            let d = Detection {
                bbox: [b[0], b[1], b[2] - b[0], b[3] - b[1]],
                score: 0.5,
                class: 0,
                mask: MaskSource::Prototypes {
                    coef: coef.clone(),
                    protos: c.protos.clone(),
                },
            };
            let coco = to_coco(&d, 7, &[3], c.input, c.orig);
            assert_eq!((coco.image_id, coco.category_id), (7, 3));
            let rle = coco
                .segmentation
                .unwrap()
                .to_rle(c.orig.1, c.orig.0)
                .unwrap();
            let lb = Letterbox::new(c.orig, c.input);
            let bx = lb.unbox_xyxy(b.map(|v| v as f64)).map(|v| v as f32);
            let want = prototype_mask(coef, &c.protos, c.orig, bx).full();
            assert_eq!(rle.decode(), want, "{:?} detection {k}", c.orig);
            let reference = from_runs(&c.case["native_runs"][k], c.orig);
            assert_eq!(
                differing(&want, &reference),
                0,
                "{:?} detection {k}",
                c.orig
            );
        }
    }
}

#[test]
fn to_coco_pastes_roi_masks_at_the_original_size() {
    // Mask R-CNN through the eval path: boxes at a letterboxed 64 px input, pasted into
    // the 150 × 90 original inside the box mapped back.
    let doc = load();
    let c = &doc["maskrcnn"][0];
    let o = ints(&c["orig"]);
    let orig = (o[0], o[1]);
    let m = c["mask_size"].as_u64().unwrap() as usize;
    let probs = floats(&c["probs"]);
    let lb = Letterbox::new(orig, 64);
    let (sx, sy) = (
        lb.inner.0 as f32 / orig.0 as f32,
        lb.inner.1 as f32 / orig.1 as f32,
    );
    let mut pasted = 0;
    for (k, bx) in boxes(&c["boxes"]).into_iter().enumerate() {
        let b = [
            bx[0] * sx + lb.pad.0 as f32,
            bx[1] * sy + lb.pad.1 as f32,
            bx[2] * sx + lb.pad.0 as f32,
            bx[3] * sy + lb.pad.1 as f32,
        ];
        let p = probs[k * m * m..(k + 1) * m * m].to_vec();
        let d = Detection {
            bbox: [b[0], b[1], b[2] - b[0], b[3] - b[1]],
            score: 0.9,
            class: 0,
            mask: MaskSource::RoiProbs {
                probs: p.clone(),
                size: m,
                threshold: 0.5,
            },
        };
        let coco = to_coco(&d, 1, &[1], 64, orig);
        let got = coco
            .segmentation
            .unwrap()
            .to_rle(orig.1, orig.0)
            .unwrap()
            .decode();
        let back = lb.unbox_xyxy(b.map(|v| v as f64)).map(|v| v as f32);
        assert_eq!(
            got,
            paste_roi_mask(&p, m, back, orig, 0.5).full(),
            "mask {k}"
        );
        assert_eq!((got.width, got.height), orig);
        pasted += usize::from(got.area() > 0);
    }
    assert_eq!(pasted, 5);
}
