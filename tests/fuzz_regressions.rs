//! Inputs the fuzz targets in `fuzz/` found (see README, "Fuzzing"), kept as regression
//! tests. Tests build without debug assertions, so where the original failure was an
//! overflow panic the test pins the value the fixed code must produce instead.

use std::path::Path;

use chicktrain::annotations::labelme;
use chicktrain::annotations::rle::Rle;

/// `rle` target, `#!ST1llllllllllllJ`: a 13-character count whose last character carries
/// the sign bit made `rleFrString`'s sign extension shift by 65 (overflow panic; without
/// overflow checks the shift wrapped to 1 and set bits 1…63).
#[test]
fn rle_count_longer_than_64_bits() {
    // The crasher itself: no panic, an error (its counts do not sum to 35 × 33).
    assert!(Rle::from_compressed("ST1llllllllllllJ", 35, 33).is_err());
    // Same shape, built to decode to one run of 16 pixels: groups 16, 0 × 11 (with the
    // continuation bit), then a last group with only the sign bit set, above bit 63.
    let s = format!("`{}@", "P".repeat(11));
    let rle = Rle::from_compressed(&s, 4, 4).expect("a 16-pixel background run");
    assert_eq!(rle.counts, vec![16]);
}

/// `labelme_json` target: a circle whose radius (3e55 px) makes labelme's vertex count
/// `π / acos(1 − 1/r)` infinite, which became a `usize::MAX`-long allocation; capped, its
/// vertices then lay ~1e55 px off the image, which the rasteriser would walk point by
/// point, so LabelMe shapes now get COCO's extent check.
#[test]
fn labelme_circle_with_a_huge_radius() {
    let text = r#"{"imagePath": "a.png", "imageHeight": 20, "imageWidth": 60, "shapes": [
        {"label": "wing", "points": [[10, 10], [33333333333333333333333333333333333333333333333333333341, 12]],
         "shape_type": "circle"}]}"#;
    let e = labelme::from_json(text, Path::new("/nonexistent/fuzz.json")).unwrap_err();
    let e = format!("{e:#}");
    assert!(
        e.contains("fuzz.json") && e.contains("\"wing\"") && e.contains("far outside"),
        "{e}"
    );
    // The same for a polygon with one vertex 1e9 px away.
    let text = r#"{"imagePath": "a.png", "imageHeight": 20, "imageWidth": 60, "shapes": [
        {"label": "wing", "points": [[1, 1], [1000000000, 5], [3, 9]]}]}"#;
    let e = format!(
        "{:#}",
        labelme::from_json(text, Path::new("x.json")).unwrap_err()
    );
    assert!(e.contains("far outside"), "{e}");
    // An ordinary circle keeps labelme's vertex count: r = 100 → 22 vertices.
    let text = r#"{"imagePath": "a.png", "imageHeight": 300, "imageWidth": 300, "shapes": [
        {"label": "wing", "points": [[150, 150], [150, 250]], "shape_type": "circle"}]}"#;
    let ds = labelme::from_json(text, Path::new("/nonexistent/fuzz.json")).unwrap();
    match &ds.annotations[0].segmentation {
        chicktrain::annotations::coco::Segmentation::Polygons(p) => assert_eq!(p[0].len(), 2 * 22),
        other => panic!("{other:?}"),
    }
}
