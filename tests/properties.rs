//! Property tests for the mask and box primitives every metric and label rests on:
//! RLE round trips, IoU bounds and symmetry, merge = pixel union/intersection, the
//! R-CNN box coder's encode/decode round trip and clamp, and that arbitrary (hostile)
//! strings and polygons give errors or results, never panics.

use chicktrain::annotations::coco::Segmentation;
use chicktrain::annotations::mask::Mask;
use chicktrain::annotations::polygon::{mask_to_polygons, rle_from_polygons};
use chicktrain::annotations::rle::{bbox_iou, rle_iou, Rle};
use chicktrain::model::maskrcnn::box_coder::BoxCoder;
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

fn mask_strategy() -> impl Strategy<Value = Mask> {
    (1u32..24, 1u32..24, 0.0f64..1.0).prop_flat_map(|(h, w, p)| {
        proptest::collection::vec(proptest::bool::weighted(p), (h * w) as usize).prop_map(
            move |bits| {
                Mask::from_row_major(h, w, bits.into_iter().map(u8::from).collect()).unwrap()
            },
        )
    })
}

/// xyxy boxes with sides from 0.5 to 1e4 px anywhere in ±1e4.
fn xyxy_strategy() -> impl Strategy<Value = [f32; 4]> {
    (-1e4f32..1e4, -1e4f32..1e4, 0.5f32..1e4, 0.5f32..1e4)
        .prop_map(|(x, y, w, h)| [x, y, x + w, y + h])
}

fn box_strategy() -> impl Strategy<Value = [f64; 4]> {
    (-50.0f64..50.0, -50.0f64..50.0, 0.0f64..60.0, 0.0f64..60.0)
        .prop_map(|(x, y, w, h)| [x, y, w, h])
}

proptest! {
    // A fixed seed: every run (and CI) draws the same cases, as every random choice in
    // chicktrain flows from a seed; a new seed is a deliberate edit, not a CI lottery.
    #![proptest_config(ProptestConfig {
        rng_seed: RngSeed::Fixed(0xC41C_4E17),
        ..ProptestConfig::with_cases(300)
    })]

    #[test]
    fn rle_round_trips(m in mask_strategy()) {
        let rle = Rle::encode(&m);
        prop_assert_eq!(rle.decode(), m.clone());
        prop_assert_eq!(rle.area(), m.area());
        let s = rle.to_compressed();
        prop_assert_eq!(Rle::from_compressed(&s, m.height, m.width).unwrap(), rle);
    }

    #[test]
    fn rle_iou_equals_pixel_iou(a in mask_strategy(), seed in any::<u64>()) {
        // a second mask of the same size
        let mut b = a.clone();
        let mut x = seed | 1;
        for v in b.data.iter_mut() {
            x ^= x << 13; x ^= x >> 7; x ^= x << 17;
            *v = (x % 3 == 0) as u8;
        }
        let (ra, rb) = (Rle::encode(&a), Rle::encode(&b));
        let iou = rle_iou(&ra, &ra.bbox(), &rb, &rb.bbox(), false);
        prop_assert!((iou - a.iou(&b)).abs() < 1e-12);
        prop_assert!((0.0..=1.0).contains(&iou));
        let union = Rle::merge(&[ra.clone(), rb.clone()], false);
        let inter = Rle::merge(&[ra, rb], true);
        let pix_union = a.data.iter().zip(&b.data).filter(|(x, y)| **x != 0 || **y != 0).count() as u64;
        let pix_inter = a.data.iter().zip(&b.data).filter(|(x, y)| **x != 0 && **y != 0).count() as u64;
        prop_assert_eq!(union.area(), pix_union);
        prop_assert_eq!(inter.area(), pix_inter);
    }

    #[test]
    fn bbox_iou_is_bounded_and_symmetric(a in box_strategy(), b in box_strategy()) {
        let ab = bbox_iou(&a, &b, false);
        let ba = bbox_iou(&b, &a, false);
        prop_assert!(ab.is_finite() && (0.0..=1.0 + 1e-12).contains(&ab), "{ab}");
        prop_assert!((ab - ba).abs() < 1e-12);
        if a[2] > 0.0 && a[3] > 0.0 {
            prop_assert!((bbox_iou(&a, &a, false) - 1.0).abs() < 1e-12);
        }
        // crowd divides by the detection's area only: never below the plain IoU
        prop_assert!(bbox_iou(&a, &b, true) + 1e-12 >= ab);
    }

    #[test]
    fn hostile_rle_strings_never_panic(s in "\\PC{0,40}", h in 0u32..50, w in 0u32..50) {
        let _ = Rle::from_compressed(&s, h, w);
    }

    #[test]
    fn hostile_polygons_error_or_rasterise(poly in proptest::collection::vec(prop_oneof![
        -1e12f64..1e12, -100.0f64..100.0, Just(f64::NAN), Just(f64::INFINITY)], 0..16),
        h in 1u32..40, w in 1u32..40) {
        let seg = Segmentation::Polygons(vec![poly]);
        if let Ok(rle) = seg.to_rle(h, w) {
            prop_assert_eq!(rle.counts.iter().map(|&c| c as u64).sum::<u64>(), (h * w) as u64);
        }
    }

    #[test]
    fn traced_polygons_cover_the_mask(m in mask_strategy()) {
        // holes are filled by COCO polygons, so the traced outline covers the mask
        let polys = mask_to_polygons(&m);
        if m.area() == 0 {
            prop_assert!(polys.is_empty());
        } else {
            let back = rle_from_polygons(&polys, m.height, m.width).decode();
            for (a, b) in m.data.iter().zip(&back.data) {
                prop_assert!(*a == 0 || *b != 0);
            }
        }
    }

    #[test]
    fn box_coder_round_trips(src in xyxy_strategy(), dst in xyxy_strategy(), roi in any::<bool>()) {
        let c = if roi { BoxCoder::roi() } else { BoxCoder::rpn() };
        let d = c.encode(src, dst);
        prop_assert!(d.iter().all(|v| v.is_finite()), "{d:?}");
        // Size ratios beyond exp(scale_clamp) = 62.5 are clamped by decode on purpose.
        let ratio = |a: f32, b: f32| (a / b).max(b / a);
        if ratio(dst[2] - dst[0], src[2] - src[0]) < 60.0 && ratio(dst[3] - dst[1], src[3] - src[1]) < 60.0 {
            let back = c.decode(d, src);
            let scale = src.iter().chain(&dst).fold(1.0f32, |m, v| m.max(v.abs()));
            for k in 0..4 {
                prop_assert!((back[k] - dst[k]).abs() <= 1e-4 * scale, "{back:?} vs {dst:?}");
            }
        }
    }

    #[test]
    fn box_decode_is_finite_and_clamped(src in xyxy_strategy(),
        d in proptest::array::uniform4(-1e3f32..1e3)) {
        let c = BoxCoder::rpn();
        let b = c.decode(d, src);
        prop_assert!(b.iter().all(|v| v.is_finite()), "{b:?}");
        prop_assert!(b[2] >= b[0] && b[3] >= b[1]);
        let max_w = (src[2] - src[0]) * c.scale_clamp.exp();
        prop_assert!(b[2] - b[0] <= max_w * (1.0 + 1e-5) + 1e-3, "{b:?} wider than {max_w}");
    }
}
