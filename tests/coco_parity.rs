//! The COCO evaluator and RLE codec against pycocotools 2.0.11.
//!
//! Fixtures: `tests/fixtures/coco/make_fixtures.py` (run with pycocotools) wrote the GT and
//! results of 34 cases, the 12 stats of each for bbox and segm, and RLE strings, areas,
//! boxes, merges and IoUs. Stats must agree bit for bit (we port numpy's pairwise mean);
//! RLE strings byte for byte.

use std::path::PathBuf;

use chicktrain::annotations::coco::{load_results, CocoDataset};
use chicktrain::annotations::mask::Mask;
use chicktrain::annotations::polygon::rle_from_polygon;
use chicktrain::annotations::rle::{rle_iou, Rle};
use chicktrain::eval::{evaluate, IouType};
use serde_json::Value;

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/coco")
}

fn read(path: PathBuf) -> Value {
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

#[test]
fn all_cases_match_pycocotools_bit_for_bit() {
    let expected = read(fixtures().join("expected.json"));
    let cases = expected.as_object().unwrap();
    assert!(
        cases.len() >= 30,
        "need at least 30 cases, have {}",
        cases.len()
    );
    let mut compared = 0;
    for (name, want) in cases {
        let gt = CocoDataset::load(&fixtures().join(format!("cases/{name}_gt.json"))).unwrap();
        let dt = load_results(&fixtures().join(format!("cases/{name}_dt.json"))).unwrap();
        for (key, iou_type) in [("bbox", IouType::Bbox), ("segm", IouType::Segm)] {
            let want: Vec<f64> = f64s(&want[key]);
            let got = evaluate(&gt, &dt, iou_type).unwrap().stats;
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    g.to_bits() == w.to_bits(),
                    "case {name} {key} stat {i}: chicktrain {g:?} vs pycocotools {w:?} (opts {})",
                    cases[name]["opts"]
                );
            }
            compared += 1;
        }
    }
    assert_eq!(compared, cases.len() * 2);
}

/// `(h, w)` of a fixture entry.
fn size(v: &Value) -> (u32, u32) {
    (
        v["h"].as_u64().unwrap() as u32,
        v["w"].as_u64().unwrap() as u32,
    )
}

/// A JSON array of numbers, exactly as f64.
fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn counts_rle(s: &str, h: u32, w: u32) -> Rle {
    Rle::from_compressed(s, h, w).unwrap()
}

#[test]
fn rle_encode_area_bbox_are_byte_identical() {
    let fx = read(fixtures().join("rle.json"));
    for m in fx["masks"].as_array().unwrap() {
        let (h, w) = size(&m);
        let data: Vec<u8> = m["rows"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| {
                r.as_str()
                    .unwrap()
                    .bytes()
                    .map(|b| b - b'0')
                    .collect::<Vec<_>>()
            })
            .collect();
        let mask = Mask::from_row_major(h, w, data).unwrap();
        let rle = Rle::encode(&mask);
        assert_eq!(rle.to_compressed(), m["counts"].as_str().unwrap());
        assert_eq!(rle.area(), m["area"].as_u64().unwrap());
        let bb: Vec<f64> = f64s(&m["bbox"]);
        assert_eq!(rle.bbox().to_vec(), bb);
        assert_eq!(
            counts_rle(m["counts"].as_str().unwrap(), h, w).decode(),
            mask
        );
    }
}

#[test]
fn polygons_rasterise_like_rle_fr_poly() {
    let fx = read(fixtures().join("rle.json"));
    for p in fx["polygons"].as_array().unwrap() {
        let (h, w) = size(&p);
        let poly: Vec<f64> = f64s(&p["poly"]);
        let rle = rle_from_polygon(&poly, h, w);
        assert_eq!(
            rle.to_compressed(),
            p["counts"].as_str().unwrap(),
            "polygon {poly:?} in {h}x{w}"
        );
        assert_eq!(rle.area(), p["area"].as_u64().unwrap());
    }
}

#[test]
fn merges_and_ious_match() {
    let fx = read(fixtures().join("rle.json"));
    for m in fx["merges"].as_array().unwrap() {
        let (h, w) = size(&m);
        let rles: Vec<Rle> = m["inputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| counts_rle(s.as_str().unwrap(), h, w))
            .collect();
        assert_eq!(
            Rle::merge(&rles, false).to_compressed(),
            m["union"].as_str().unwrap()
        );
        assert_eq!(
            Rle::merge(&rles, true).to_compressed(),
            m["intersection"].as_str().unwrap()
        );
    }
    for c in fx["ious"].as_array().unwrap() {
        let (h, w) = size(&c);
        let d = counts_rle(c["dt"].as_str().unwrap(), h, w);
        let g = counts_rle(c["gt"].as_str().unwrap(), h, w);
        let iou = rle_iou(&d, &d.bbox(), &g, &g.bbox(), c["crowd"].as_bool().unwrap());
        assert_eq!(iou, c["iou"].as_f64().unwrap());
    }
}
