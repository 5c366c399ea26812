//! Writing rendered samples out: COCO annotations (pycocotools-compatible compressed RLE
//! in `segmentation`, polygons — several per instance where occlusion splits it — in
//! `polygons`, `area` = pixel count, `bbox` from the mask, plus `visib_fract`,
//! `amodal_bbox`, `amodal_area`, `resting`, `truncated`) through the data layer, and the
//! preview contact sheet (coloured mask overlays, boxes; ignored instances hatched).

use image::{imageops, Rgb, RgbImage};
use serde_json::{json, Map, Value};

use crate::annotations::coco::{CocoAnnotation, Segmentation};
use crate::annotations::mask::Mask;
use crate::annotations::polygon::mask_to_polygons;
use crate::annotations::rle::Rle;

use super::labels::InstanceLabel;

/// COCO category id of "carcass".
pub const CARCASS_CATEGORY: u64 = 1;

/// Visible mask of one instance, straight from the id buffer.
pub fn visible_mask(ids: &[u16], width: u32, height: u32, id: u16) -> Mask {
    Mask {
        height,
        width,
        data: ids.iter().map(|&v| (v == id) as u8).collect(),
    }
}

/// COCO annotations of one image; ids start at `first_id`.
pub fn annotations(
    ids: &[u16],
    width: u32,
    height: u32,
    instances: &[InstanceLabel],
    image_id: u64,
    first_id: u64,
) -> Vec<CocoAnnotation> {
    instances
        .iter()
        .enumerate()
        .map(|(k, inst)| {
            let mask = visible_mask(ids, width, height, inst.id);
            let rle = Rle::encode(&mask);
            let polys: Vec<Vec<f64>> = mask_to_polygons(&mask);
            let mut extra = Map::new();
            extra.insert("polygons".into(), json!(polys));
            extra.insert("visib_fract".into(), json!(inst.visib_fract));
            extra.insert("amodal_bbox".into(), json!(inst.amodal_bbox));
            extra.insert("amodal_area".into(), json!(inst.amodal_px));
            extra.insert("resting".into(), Value::String(inst.resting.clone()));
            extra.insert("truncated".into(), json!(inst.truncated));
            extra.insert("ignore".into(), json!(inst.ignore as u8));
            CocoAnnotation {
                id: first_id + k as u64,
                image_id,
                category_id: CARCASS_CATEGORY,
                segmentation: Segmentation::Rle {
                    size: [height, width],
                    counts: rle.to_compressed(),
                },
                area: rle.area() as f64,
                bbox: rle.bbox(),
                iscrowd: inst.ignore as u8,
                extra,
            }
        })
        .collect()
}

/// A distinct, saturated colour per instance id.
pub fn instance_color(id: u16) -> [u8; 3] {
    let h = (id as f32 * 0.618_034).fract() * 6.0;
    let x = (1.0 - ((h % 2.0) - 1.0).abs()) * 255.0;
    let (r, g, b) = match h as u32 {
        0 => (255.0, x, 0.0),
        1 => (x, 255.0, 0.0),
        2 => (0.0, 255.0, x),
        3 => (0.0, x, 255.0),
        4 => (x, 0.0, 255.0),
        _ => (255.0, 0.0, x),
    };
    [r as u8, g as u8, b as u8]
}

/// One preview tile: the image with translucent instance colours, mask outlines and
/// boxes (ignored instances: hatched, dashed box), downscaled to `tile` pixels wide.
pub fn overlay_tile(
    image: &RgbImage,
    ids: &[u16],
    instances: &[InstanceLabel],
    tile: u32,
) -> RgbImage {
    let (w, h) = image.dimensions();
    let mut out = image.clone();
    let ignore: std::collections::HashSet<u16> = instances
        .iter()
        .filter(|i| i.ignore)
        .map(|i| i.id)
        .collect();
    let kept: std::collections::HashSet<u16> = instances.iter().map(|i| i.id).collect();
    for y in 0..h {
        for x in 0..w {
            let id = ids[(y * w + x) as usize];
            if id == 0 || !kept.contains(&id) {
                continue;
            }
            let c = instance_color(id);
            let edge = [(1i32, 0i32), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|(dx, dy)| {
                    let (xx, yy) = (x as i32 + dx, y as i32 + dy);
                    xx < 0
                        || yy < 0
                        || xx >= w as i32
                        || yy >= h as i32
                        || ids[(yy as u32 * w + xx as u32) as usize] != id
                });
            let p = out.get_pixel_mut(x, y);
            let a = if edge {
                1.0
            } else if ignore.contains(&id) {
                if (x + y) % 8 < 2 {
                    0.6
                } else {
                    0.0
                }
            } else {
                0.35
            };
            for ch in 0..3 {
                p[ch] = (p[ch] as f32 * (1.0 - a) + c[ch] as f32 * a) as u8;
            }
        }
    }
    for inst in instances {
        let c = Rgb(instance_color(inst.id));
        let [bx, by, bw, bh] = inst.bbox.map(|v| v as u32);
        let dashed = inst.ignore;
        for t in 0..2 {
            for x in bx..(bx + bw).min(w) {
                for y in [by + t, (by + bh).saturating_sub(1 + t)] {
                    if y < h && (!dashed || (x / 6) % 2 == 0) {
                        out.put_pixel(x, y, c);
                    }
                }
            }
            for y in by..(by + bh).min(h) {
                for x in [bx + t, (bx + bw).saturating_sub(1 + t)] {
                    if x < w && (!dashed || (y / 6) % 2 == 0) {
                        out.put_pixel(x, y, c);
                    }
                }
            }
        }
    }
    let th = (tile as f32 * h as f32 / w as f32).round().max(1.0) as u32;
    imageops::resize(&out, tile, th, imageops::FilterType::Triangle)
}

/// Lays tiles out on a grid (`cols` wide) with a 4 px dark gutter.
pub fn contact_sheet(tiles: &[RgbImage], cols: u32) -> RgbImage {
    let cols = cols.max(1).min(tiles.len().max(1) as u32);
    let rows = (tiles.len() as u32).div_ceil(cols).max(1);
    let tw = tiles.iter().map(|t| t.width()).max().unwrap_or(1);
    let th = tiles.iter().map(|t| t.height()).max().unwrap_or(1);
    let g = 4;
    let mut sheet =
        RgbImage::from_pixel(cols * (tw + g) + g, rows * (th + g) + g, Rgb([20, 20, 24]));
    for (i, t) in tiles.iter().enumerate() {
        let (c, r) = (i as u32 % cols, i as u32 / cols);
        imageops::replace(
            &mut sheet,
            t,
            (g + c * (tw + g)) as i64,
            (g + r * (th + g)) as i64,
        );
    }
    sheet
}

#[cfg(test)]
mod tests {
    use super::*;

    fn label(id: u16, ignore: bool) -> InstanceLabel {
        InstanceLabel {
            id,
            visible_px: 0,
            amodal_px: 0,
            visib_fract: 1.0,
            bbox: [0.0; 4],
            amodal_bbox: [0.0; 4],
            ignore,
            resting: "side".into(),
            truncated: false,
        }
    }

    #[test]
    fn annotations_match_the_id_buffer() {
        // 8x6 image: instance 1 split in two parts by instance 2.
        let (w, h) = (8u32, 6u32);
        let mut ids = vec![0u16; 48];
        for y in 1..5 {
            for x in 1..7 {
                ids[y * 8 + x] = if x == 3 || x == 4 { 2 } else { 1 };
            }
        }
        let anns = annotations(&ids, w, h, &[label(1, false), label(2, true)], 7, 100);
        assert_eq!(anns.len(), 2);
        assert_eq!(anns[0].area, 16.0);
        assert_eq!(anns[0].bbox, [1.0, 1.0, 6.0, 4.0]);
        assert_eq!(anns[1].iscrowd, 1);
        assert_eq!(anns[1].id, 101);
        let polys = anns[0].extra["polygons"].as_array().unwrap();
        assert_eq!(
            polys.len(),
            2,
            "occlusion splits instance 1 into two polygons"
        );
        let Segmentation::Rle { size, counts } = &anns[0].segmentation else {
            panic!()
        };
        assert_eq!(*size, [6, 8]);
        let back = Rle::from_compressed(counts, 6, 8).unwrap().decode();
        assert_eq!(back, visible_mask(&ids, w, h, 1));
    }

    #[test]
    fn sheet_has_expected_size() {
        let t = RgbImage::new(10, 10);
        let s = contact_sheet(&[t.clone(), t.clone(), t], 2);
        assert_eq!(s.dimensions(), (2 * 14 + 4, 2 * 14 + 4));
    }
}
