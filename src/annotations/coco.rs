//! COCO dataset and results files: reading, validating, writing.
//!
//! Real COCO files carry extra fields (`info`, `licenses`, `supercategory`, `flickr_url`,
//! the renderer's `visib_fract`); they are kept in `extra` maps and written back, never
//! rejected. Everything the evaluator or trainer relies on is checked once here, with
//! messages that name the file and the offending entry, so later stages can trust it.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use serde_json::{Map, Value};

use super::polygon::rle_from_polygons;
use super::rle::Rle;

/// One instance outline: polygons (several parts allowed), compressed or raw RLE.
#[derive(Clone, Debug, PartialEq)]
pub enum Segmentation {
    Polygons(Vec<Vec<f64>>),
    /// `{"size": [h, w], "counts": "..."}` as pycocotools writes it.
    Rle {
        size: [u32; 2],
        counts: String,
    },
    /// `{"size": [h, w], "counts": [..]}`, COCO's crowd format, and the in-memory form.
    Uncompressed(Rle),
}

impl Segmentation {
    /// The mask as pycocotools' `annToRLE` builds it for an image of `height`×`width`.
    pub fn to_rle(&self, height: u32, width: u32) -> Result<Rle> {
        Ok(match self {
            Segmentation::Polygons(polys) => {
                check_polygons(polys)?;
                check_polygon_extent(polys, height, width)?;
                rle_from_polygons(polys, height, width)
            }
            Segmentation::Rle { size, counts } => {
                check_size(*size, height, width)?;
                Rle::from_compressed(counts, size[0], size[1])?
            }
            Segmentation::Uncompressed(rle) => {
                check_size([rle.height, rle.width], height, width)?;
                rle.check_total()?;
                rle.clone()
            }
        })
    }

    /// The checks of [`Segmentation::to_rle`] without rasterising polygons, so loading a
    /// file validates it at the cost of parsing it.
    pub fn check(&self, height: u32, width: u32) -> Result<()> {
        match self {
            Segmentation::Polygons(polys) => {
                check_polygons(polys)?;
                check_polygon_extent(polys, height, width)
            }
            _ => self.to_rle(height, width).map(|_| ()),
        }
    }

    /// Compressed RLE of a mask, the form chicktrain writes.
    pub fn from_rle(rle: &Rle) -> Segmentation {
        Segmentation::Rle {
            size: [rle.height, rle.width],
            counts: rle.to_compressed(),
        }
    }
}

fn check_size(size: [u32; 2], height: u32, width: u32) -> Result<()> {
    if size != [height, width] {
        bail!(
            "RLE size [{}, {}] disagrees with its image's [height, width] = [{height}, {width}]",
            size[0],
            size[1]
        );
    }
    Ok(())
}

/// Polygons need 3 points (pycocotools would read a 2-point one as a box, silently).
pub fn check_polygons(polys: &[Vec<f64>]) -> Result<()> {
    if polys.is_empty() {
        bail!("segmentation is an empty list of polygons");
    }
    for (i, p) in polys.iter().enumerate() {
        if p.len() < 6 {
            bail!(
                "polygon {i} has {} coordinates; a polygon needs at least 3 points (6 numbers)",
                p.len()
            );
        }
        if p.len() % 2 != 0 {
            bail!("polygon {i} has an odd number of coordinates ({})", p.len());
        }
        if p.iter().any(|v| !v.is_finite()) {
            bail!("polygon {i} has a non-finite coordinate");
        }
    }
    Ok(())
}

/// pycocotools walks every polygon edge at 5× resolution, so a coordinate of 1e9 would
/// allocate billions of points; anything that far off the image is a broken file.
fn check_polygon_extent(polys: &[Vec<f64>], height: u32, width: u32) -> Result<()> {
    let limit = 10.0 * (height.max(width) as f64 + 1.0);
    for (i, p) in polys.iter().enumerate() {
        if let Some(v) = p.iter().find(|v| v.abs() > limit) {
            bail!(
                "polygon {i} has a coordinate {v} far outside its {width}x{height} image (limit ±{limit})"
            );
        }
    }
    Ok(())
}

impl Serialize for Segmentation {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Segmentation::Polygons(p) => p.serialize(s),
            Segmentation::Rle { size, counts } => {
                serde_json::json!({"size": size, "counts": counts}).serialize(s)
            }
            Segmentation::Uncompressed(r) => {
                serde_json::json!({"size": [r.height, r.width], "counts": r.counts}).serialize(s)
            }
        }
    }
}

impl<'de> Deserialize<'de> for Segmentation {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error;
        let v = Value::deserialize(d)?;
        segmentation_from_value(&v).map_err(D::Error::custom)
    }
}

fn segmentation_from_value(v: &Value) -> std::result::Result<Segmentation, String> {
    match v {
        Value::Array(polys) => {
            let mut out = Vec::with_capacity(polys.len());
            for p in polys {
                let Value::Array(coords) = p else {
                    return Err("segmentation: each polygon must be a list of numbers".into());
                };
                let mut poly = Vec::with_capacity(coords.len());
                for c in coords {
                    poly.push(
                        c.as_f64()
                            .ok_or("segmentation: polygon coordinate is not a number")?,
                    );
                }
                out.push(poly);
            }
            Ok(Segmentation::Polygons(out))
        }
        Value::Object(o) => {
            let size = o
                .get("size")
                .and_then(|s| s.as_array())
                .filter(|s| s.len() == 2)
                .and_then(|s| Some([s[0].as_u64()? as u32, s[1].as_u64()? as u32]))
                .ok_or("segmentation RLE needs \"size\": [height, width]")?;
            match o.get("counts") {
                Some(Value::String(c)) => Ok(Segmentation::Rle {
                    size,
                    counts: c.clone(),
                }),
                Some(Value::Array(c)) => {
                    let counts = c
                        .iter()
                        .map(|x| {
                            x.as_u64()
                                .filter(|&x| x <= u32::MAX as u64)
                                .map(|x| x as u32)
                        })
                        .collect::<Option<Vec<u32>>>()
                        .ok_or("segmentation RLE counts must be non-negative integers")?;
                    Ok(Segmentation::Uncompressed(Rle {
                        height: size[0],
                        width: size[1],
                        counts,
                    }))
                }
                _ => Err("segmentation RLE needs \"counts\" (a string or a list)".into()),
            }
        }
        _ => Err("segmentation must be a list of polygons or an RLE object".into()),
    }
}

/// COCO allows `iscrowd` as 0/1; some tools write booleans.
fn de_flag<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<u8, D::Error> {
    use serde::de::Error;
    match Value::deserialize(d)? {
        Value::Bool(b) => Ok(b as u8),
        Value::Number(n) if n.as_u64() == Some(0) || n.as_u64() == Some(1) => {
            Ok(n.as_u64().unwrap_or(0) as u8)
        }
        other => Err(D::Error::custom(format!(
            "iscrowd must be 0 or 1, got {other}"
        ))),
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CocoImage {
    pub id: u64,
    pub file_name: String,
    pub width: u32,
    pub height: u32,
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CocoCategory {
    pub id: u64,
    pub name: String,
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CocoAnnotation {
    pub id: u64,
    pub image_id: u64,
    pub category_id: u64,
    pub segmentation: Segmentation,
    pub area: f64,
    pub bbox: [f64; 4],
    #[serde(default, deserialize_with = "de_flag")]
    pub iscrowd: u8,
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// A COCO instances file.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct CocoDataset {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info: Option<Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub licenses: Option<Value>,
    pub images: Vec<CocoImage>,
    #[serde(default)]
    pub annotations: Vec<CocoAnnotation>,
    pub categories: Vec<CocoCategory>,
}

impl CocoDataset {
    /// The categories as sorted `(id, name)` pairs: what two sets must share to be one
    /// dataset (the splits of one COCO set, the parts of one YOLO export).
    pub fn sorted_categories(&self) -> Vec<(u64, String)> {
        let mut c: Vec<(u64, String)> = self
            .categories
            .iter()
            .map(|c| (c.id, c.name.clone()))
            .collect();
        c.sort();
        c
    }

    /// Reads and validates a COCO file; errors name the file, the line or the entry.
    pub fn load(path: &Path) -> Result<CocoDataset> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read COCO file {}", path.display()))?;
        let ds =
            Self::from_json(&text).with_context(|| format!("in COCO file {}", path.display()))?;
        Ok(ds)
    }

    /// Parses and validates COCO JSON text.
    pub fn from_json(text: &str) -> Result<CocoDataset> {
        let ds: CocoDataset = serde_json::from_str(text).context("invalid COCO JSON")?;
        ds.validate()?;
        Ok(ds)
    }

    /// Writes the file (pretty enough to diff, compact enough for 1000 images).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self)?;
        crate::util::write_atomic(path, text.as_bytes())
    }

    /// Checks ids, references, boxes, areas and segmentations.
    pub fn validate(&self) -> Result<()> {
        let mut images: HashMap<u64, &CocoImage> = HashMap::new();
        for im in &self.images {
            if images.insert(im.id, im).is_some() {
                bail!("image id {} appears twice", im.id);
            }
            if im.width == 0 || im.height == 0 {
                bail!(
                    "image {} ({}) has zero width or height",
                    im.id,
                    im.file_name
                );
            }
        }
        let mut cats = HashSet::new();
        for c in &self.categories {
            if !cats.insert(c.id) {
                bail!("category id {} appears twice", c.id);
            }
        }
        let mut ann_ids = HashSet::new();
        for a in &self.annotations {
            let ctx = || format!("annotation id {} (image {})", a.id, a.image_id);
            if !ann_ids.insert(a.id) {
                bail!("annotation id {} appears twice", a.id);
            }
            let Some(im) = images.get(&a.image_id) else {
                bail!("{}: image_id {} is not among the images", ctx(), a.image_id);
            };
            if !cats.contains(&a.category_id) {
                bail!(
                    "{}: category_id {} is not among the categories",
                    ctx(),
                    a.category_id
                );
            }
            if a.bbox.iter().any(|v| !v.is_finite()) || a.bbox[2] < 0.0 || a.bbox[3] < 0.0 {
                bail!(
                    "{}: bbox {:?} has a negative or non-finite size",
                    ctx(),
                    a.bbox
                );
            }
            if !a.area.is_finite() || a.area < 0.0 {
                bail!("{}: area {} is negative or not finite", ctx(), a.area);
            }
            a.segmentation
                .check(im.height, im.width)
                .with_context(ctx)?;
        }
        Ok(())
    }

    pub fn image(&self, id: u64) -> Option<&CocoImage> {
        self.images.iter().find(|im| im.id == id)
    }
}

/// One detection, as in a COCO results file (and as the trainer hands them over).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Detection {
    pub image_id: u64,
    pub category_id: u64,
    pub score: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bbox: Option<[f64; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segmentation: Option<Segmentation>,
}

/// Reads a results file (a JSON list of detections).
pub fn load_results(path: &Path) -> Result<Vec<Detection>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read results file {}", path.display()))?;
    let dets: Vec<Detection> = serde_json::from_str(&text)
        .with_context(|| format!("invalid COCO results JSON in {}", path.display()))?;
    for (i, d) in dets.iter().enumerate() {
        if !d.score.is_finite() {
            bail!("{}: detection {i} has a non-finite score", path.display());
        }
        if let Some(b) = d.bbox {
            if b.iter().any(|v| !v.is_finite()) {
                bail!(
                    "{}: detection {i} has a non-finite bbox {b:?}",
                    path.display()
                );
            }
        }
    }
    Ok(dets)
}

/// Writes a results file.
pub fn save_results(path: &Path, dets: &[Detection]) -> Result<()> {
    crate::util::write_atomic(path, serde_json::to_string(dets)?.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"{"info": {"year": 2026}, "licenses": [], "type": "instances",
      "images": [{"id": 1, "file_name": "a.jpg", "width": 6, "height": 5, "flickr_url": "x"}],
      "categories": [{"id": 1, "name": "carcass", "supercategory": "poultry"}],
      "annotations": [{"id": 7, "image_id": 1, "category_id": 1, "iscrowd": 0,
        "segmentation": [[1, 1, 4, 1, 4, 3, 1, 3]], "area": 6, "bbox": [1, 1, 3, 2]}]}"#;

    #[test]
    fn reads_extra_fields_and_writes_them_back() {
        let ds = CocoDataset::from_json(SMALL).unwrap();
        assert_eq!(ds.images[0].extra["flickr_url"], "x");
        assert_eq!(ds.categories[0].extra["supercategory"], "poultry");
        let again = CocoDataset::from_json(&serde_json::to_string(&ds).unwrap()).unwrap();
        assert_eq!(again, ds);
    }

    #[test]
    fn bad_entries_are_named() {
        let cases = [
            (
                SMALL.replace("\"image_id\": 1", "\"image_id\": 9"),
                "image_id 9",
            ),
            (
                SMALL.replace("\"category_id\": 1", "\"category_id\": 3"),
                "category_id 3",
            ),
            (SMALL.replace("[1, 1, 3, 2]", "[1, 1, -3, 2]"), "negative"),
            (
                SMALL.replace("[[1, 1, 4, 1, 4, 3, 1, 3]]", "[[1, 1, 4, 1]]"),
                "at least 3 points",
            ),
            (
                SMALL.replace(
                    "[[1, 1, 4, 1, 4, 3, 1, 3]]",
                    r#"{"size": [4, 4], "counts": "52203"}"#,
                ),
                "disagrees",
            ),
            (
                SMALL.replace("\"segmentation\"", "\"segmentatio\""),
                "missing field `segmentation`",
            ),
            (SMALL[..SMALL.len() - 10].to_string(), "invalid COCO JSON"),
        ];
        for (text, needle) in cases {
            let err = format!("{:#}", CocoDataset::from_json(&text).unwrap_err());
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
        }
    }
}
