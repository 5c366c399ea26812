//! LabelMe import against labelme's own `labelme2coco.py` output on LabelMe files of our
//! own (`tests/fixtures/labelme/`, made by its `make_fixture.py`: labelme's example
//! annotations are GPL-3.0 and stay out of this repository).
//!
//! Instances, categories and polygons must be identical. Areas and boxes are computed
//! with pycocotools' rasteriser, which leaves out the one-pixel outline that labelme's
//! PIL drawing adds, so they are at most that much smaller: checked as such.

use std::collections::HashMap;
use std::path::PathBuf;

use chicktrain::annotations::coco::{CocoDataset, Segmentation};
use chicktrain::annotations::labelme;

fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/labelme")
}

#[test]
fn matches_labelme2coco_on_our_fixture() {
    let dir = examples();
    let labels = labelme::read_labels(&dir.join("labels.txt")).unwrap();
    let ours = labelme::load_dir(&dir.join("data_annotated"), Some(&labels)).unwrap();
    let theirs: CocoDataset = serde_json::from_str(
        &std::fs::read_to_string(dir.join("labelme2coco_annotations.json")).unwrap(),
    )
    .unwrap();
    let name = |ds: &CocoDataset, image_id: u64| -> String {
        let f = &ds
            .images
            .iter()
            .find(|i| i.id == image_id)
            .unwrap()
            .file_name;
        f.rsplit('/').next().unwrap().to_string()
    };
    let cat = |ds: &CocoDataset, id: u64| {
        ds.categories
            .iter()
            .find(|c| c.id == id)
            .unwrap()
            .name
            .clone()
    };
    let mut per_image: HashMap<String, Vec<_>> = HashMap::new();
    for a in &theirs.annotations {
        per_image
            .entry(name(&theirs, a.image_id))
            .or_default()
            .push(a);
    }
    assert_eq!(ours.images.len(), 3);
    assert_eq!(ours.annotations.len(), theirs.annotations.len());
    assert!(!ours.categories.iter().any(|c| c.name.starts_with('_')));
    for im in &ours.images {
        let mine: Vec<_> = ours
            .annotations
            .iter()
            .filter(|a| a.image_id == im.id)
            .collect();
        let want = &per_image[&name(&ours, im.id)];
        assert_eq!(mine.len(), want.len(), "{}", im.file_name);
        for (a, b) in mine.iter().zip(want.iter()) {
            assert_eq!(cat(&ours, a.category_id), cat(&theirs, b.category_id));
            assert_eq!(a.segmentation, b.segmentation);
            assert!(matches!(a.segmentation, Segmentation::Polygons(_)));
            // labelme's PIL masks add a one-pixel outline: ours lie inside theirs.
            assert!(
                a.area <= b.area && a.area >= 0.93 * b.area,
                "{} vs {}",
                a.area,
                b.area
            );
            assert!(a.bbox[0] >= b.bbox[0] && a.bbox[0] <= b.bbox[0] + 1.0);
            assert!(a.bbox[1] >= b.bbox[1] && a.bbox[1] <= b.bbox[1] + 1.0);
            assert!(a.bbox[2] <= b.bbox[2] && a.bbox[2] >= b.bbox[2] - 2.0);
            assert!(a.bbox[3] <= b.bbox[3] && a.bbox[3] >= b.bbox[3] - 2.0);
        }
    }
    // the two-part carcass (group_id 0) stays one instance with two polygons
    let two_part = ours
        .annotations
        .iter()
        .filter(|a| matches!(&a.segmentation, Segmentation::Polygons(p) if p.len() == 2))
        .count();
    assert!(two_part >= 1);
}

fn write(dir: &std::path::Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap();
}

#[test]
fn rectangles_groups_and_bad_shapes() {
    let dir = std::env::temp_dir().join(format!("ct-labelme-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    write(
        &dir,
        "a.json",
        r#"{"version": "5.0.1", "flags": {}, "imagePath": "a.png", "imageData": null,
            "imageHeight": 20, "imageWidth": 30, "shapes": [
          {"label": "carcass", "points": [[12, 2], [2, 8]], "group_id": null, "shape_type": "rectangle", "flags": {}},
          {"label": "carcass", "points": [[20, 2], [28, 2], [28, 10]], "group_id": 3, "shape_type": "polygon", "flags": {}},
          {"label": "carcass", "points": [[20, 12], [28, 12], [28, 18]], "group_id": 3, "shape_type": "polygon", "flags": {}},
          {"label": "__ignore__", "points": [[0, 0], [1, 0], [1, 1]], "group_id": null, "shape_type": "polygon", "flags": {}},
          {"label": "carcass", "points": [[5, 15]], "group_id": null, "shape_type": "point", "flags": {}}
        ]}"#,
    );
    let ds = labelme::load_dir(&dir, None).unwrap();
    assert_eq!(ds.categories.len(), 1);
    assert_eq!(ds.annotations.len(), 2);
    let rect = &ds.annotations[0];
    assert_eq!(
        rect.segmentation,
        Segmentation::Polygons(vec![vec![2.0, 2.0, 12.0, 2.0, 12.0, 8.0, 2.0, 8.0]])
    );
    assert_eq!(rect.area, 60.0);
    assert_eq!(rect.bbox, [2.0, 2.0, 10.0, 6.0]);
    assert!(matches!(&ds.annotations[1].segmentation, Segmentation::Polygons(p) if p.len() == 2));

    write(
        &dir,
        "b.json",
        r#"{"imagePath": "b.png", "imageHeight": 20, "imageWidth": 30, "shapes": [
          {"label": "carcass", "points": [[1, 1], [5, 5]], "shape_type": "polygon"}]}"#,
    );
    let err = format!("{:#}", labelme::load_dir(&dir, None).unwrap_err());
    assert!(
        err.contains("b.json") && err.contains("at least 3 points"),
        "{err}"
    );
    write(
        &dir,
        "b.json",
        r#"{"imagePath": "b.png", "imageHeight": 20, "#,
    );
    let err = format!("{:#}", labelme::load_dir(&dir, None).unwrap_err());
    assert!(
        err.contains("b.json") && err.contains("invalid LabelMe JSON"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
