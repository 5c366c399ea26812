//! YOLO-seg datasets in (ultralytics and Roboflow's layout): `data.yaml` ([`DataYaml`]),
//! image folders or lists per split, and one `labels/…/<stem>.txt` per image with a line
//! `class x1 y1 x2 y2 …` per instance, coordinates normalised to [0, 1]. The inverse of
//! [`super::yolo_export`].
//!
//! Read by ultralytics' rules (`ultralytics/data/utils.py`): a split's folder is searched
//! recursively for files with an image extension (`IMG_FORMATS`); a `.txt` list gives
//! one image per line (`./x` relative to the list's folder; chicktrain reads other
//! relative lines from there too, where ultralytics uses the working directory); an
//! image's label file is its path with the last `images` folder replaced by `labels` and
//! the extension by `.txt` (`img2label_paths`); an image without one has no instances.
//! Exact duplicate lines are dropped with a warning, as ultralytics does.
//!
//! The result is what the COCO and LabelMe readers give: a [`CocoDataset`] at the images'
//! own sizes (polygons scaled by width and height, rasterised by pycocotools' rules for
//! area and box), categories `1..=n` named by `names` in class order, plus the split the
//! yaml declares ([`OwnSplit`]). A yaml whose `train` and `val` are the same images (what
//! `convert coco2yolo` writes for one unsplit COCO file, and an ultralytics habit for
//! small sets) declares no split: the run draws its own.
//!
//! Every malformed label line is an error naming `file:line`: a class id that is not a
//! whole number or not below the number of `names`, a coordinate that is not a number or
//! lies outside [0, 1] by more than [`TOLERANCE`], an odd number of coordinates, fewer
//! than 3 points, a detection-only box line.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde_json::Map;

use super::coco::{CocoAnnotation, CocoCategory, CocoDataset, CocoImage, Segmentation};
use super::image_file::image_dimensions;
use super::split::{OwnSplit, Part};
use super::yolo_yaml::DataYaml;

/// ultralytics' `IMG_FORMATS`: the extensions a split folder is searched for. chicktrain
/// decodes PNG and JPEG; a file of another of these formats fails naming it.
pub const IMG_FORMATS: [&str; 11] = [
    "bmp", "dng", "jpeg", "jpg", "mpo", "png", "tif", "tiff", "webp", "pfm", "heic",
];

/// How far outside [0, 1] a coordinate may lie before a label line is rejected
/// (ultralytics' tolerance below 0); within it, coordinates are clamped.
pub const TOLERANCE: f64 = 0.01;

/// A YOLO-seg dataset as ground truth.
#[derive(Clone, Debug)]
pub struct YoloDataset {
    /// Images (ids `1..`, train then val then test, each sorted by path) and instances.
    pub coco: CocoDataset,
    /// What image `file_name`s are relative to (the yaml's dataset root).
    pub root: PathBuf,
    /// The yaml's split; `None` when `train` and `val` are the same images.
    pub own_split: Option<OwnSplit>,
}

/// One label line: class index and its polygon, normalised.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelLine {
    pub class: usize,
    pub points: Vec<[f64; 2]>,
}

/// Reads the dataset `yaml` names: images, their sizes and label files.
pub fn load(yaml: &Path) -> Result<YoloDataset> {
    let data = DataYaml::load(yaml)?;
    let mut parts: Vec<(Part, Vec<PathBuf>)> = Vec::new();
    for part in Part::ALL {
        let mut files = Vec::new();
        for src in data.part(part) {
            files.extend(
                images_of(src)
                    .with_context(|| format!("`{}` of {}", part.key(), data.file.display()))?,
            );
        }
        files.sort();
        files.dedup();
        parts.push((part, files));
    }
    let same_train_val = parts[0].1 == parts[1].1;
    if !same_train_val {
        check_disjoint(&parts, &data.file)?;
    }
    let mut images: Vec<(PathBuf, Part)> = Vec::new();
    let mut seen = HashSet::new();
    for (part, files) in &parts {
        for f in files {
            if seen.insert(f.clone()) {
                images.push((f.clone(), *part));
            }
        }
    }
    let n = data.names.len();
    let read: Vec<(CocoImage, Vec<LabelLine>)> = images
        .par_iter()
        .enumerate()
        .map(|(i, (path, _))| read_one(path, i as u64 + 1, &data.root, n))
        .collect::<Result<_>>()?;
    let mut coco = CocoDataset {
        categories: data
            .names
            .iter()
            .enumerate()
            .map(|(i, name)| CocoCategory {
                id: i as u64 + 1,
                name: name.clone(),
                extra: Map::new(),
            })
            .collect(),
        ..Default::default()
    };
    for (im, lines) in read {
        for l in lines {
            let poly: Vec<f64> = l
                .points
                .iter()
                .flat_map(|[x, y]| [x * im.width as f64, y * im.height as f64])
                .collect();
            let segmentation = Segmentation::Polygons(vec![poly]);
            let rle = segmentation.to_rle(im.height, im.width)?;
            coco.annotations.push(CocoAnnotation {
                id: coco.annotations.len() as u64 + 1,
                image_id: im.id,
                category_id: l.class as u64 + 1,
                area: rle.area() as f64,
                bbox: rle.bbox(),
                segmentation,
                iscrowd: 0,
                extra: Map::new(),
            });
        }
        coco.images.push(im);
    }
    let own_split = (!same_train_val).then(|| {
        let mut own = OwnSplit::default();
        for (i, (_, part)) in images.iter().enumerate() {
            own.push(*part, i as u64 + 1);
        }
        own
    });
    Ok(YoloDataset {
        coco,
        root: data.root,
        own_split,
    })
}

/// Train, val and test must not share an image (it would be scored on what it learnt).
fn check_disjoint(parts: &[(Part, Vec<PathBuf>)], yaml: &Path) -> Result<()> {
    for i in 0..parts.len() {
        for j in i + 1..parts.len() {
            let b: HashSet<&PathBuf> = parts[j].1.iter().collect();
            let shared: Vec<&PathBuf> = parts[i].1.iter().filter(|f| b.contains(f)).collect();
            if let Some(first) = shared.first() {
                bail!(
                    "{}: `{}` and `{}` share {} images (e.g. {}); the splits must be disjoint (or `train` and `val` the same images, for no split of its own)",
                    yaml.display(),
                    parts[i].0.key(),
                    parts[j].0.key(),
                    shared.len(),
                    first.display()
                );
            }
        }
    }
    Ok(())
}

/// The image files of one split source: a folder (searched recursively) or a `.txt`
/// list; sorted.
pub fn images_of(src: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    if src.is_dir() {
        walk(src, &mut out)?;
        if out.is_empty() {
            bail!(
                "no images ({}) in {}",
                IMG_FORMATS.join(", "),
                src.display()
            );
        }
    } else if src.is_file() {
        let text = std::fs::read_to_string(src)
            .with_context(|| format!("cannot read image list {}", src.display()))?;
        let dir = src.parent().unwrap_or(Path::new(""));
        for (ln, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let p = dir.join(line.strip_prefix("./").unwrap_or(line));
            if !has_image_extension(&p) {
                continue;
            }
            if !p.is_file() {
                bail!(
                    "{}:{}: image {} does not exist",
                    src.display(),
                    ln + 1,
                    p.display()
                );
            }
            out.push(p);
        }
        if out.is_empty() {
            bail!("image list {} names no image files", src.display());
        }
    } else {
        bail!("{} does not exist", src.display());
    }
    out.sort();
    Ok(out)
}

fn has_image_extension(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMG_FORMATS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Files with an image extension under `dir`, hidden ones left out (ultralytics' glob
/// `**/*.*` skips them).
fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot read folder {}", dir.display()))?;
    for e in entries {
        let e = e.with_context(|| format!("cannot read folder {}", dir.display()))?;
        let p = e.path();
        if e.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        if p.is_dir() {
            walk(&p, out)?;
        } else if has_image_extension(&p) {
            out.push(p);
        }
    }
    Ok(())
}

/// ultralytics' `img2label_paths`: the last `images` folder of the path becomes
/// `labels`, the extension `.txt` (a path without an `images` folder keeps its folder).
pub fn label_path(image: &Path) -> PathBuf {
    let comps: Vec<_> = image.components().collect();
    let folders = &comps[..comps.len().saturating_sub(1)];
    let last_images = folders.iter().rposition(|c| c.as_os_str() == "images");
    let mut p = PathBuf::new();
    for (i, c) in comps.iter().enumerate() {
        if Some(i) == last_images {
            p.push("labels");
        } else {
            p.push(c.as_os_str());
        }
    }
    p.set_extension("txt");
    p
}

/// Image `path` as COCO image `id` (size from its header) and its label lines.
fn read_one(
    path: &Path,
    id: u64,
    root: &Path,
    classes: usize,
) -> Result<(CocoImage, Vec<LabelLine>)> {
    let (width, height) = image_dimensions(path)?;
    let label = label_path(path);
    let lines = match std::fs::read_to_string(&label) {
        Ok(text) => parse_labels(&text, &label, classes)?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => bail!("cannot read label file {}: {e}", label.display()),
    };
    let file_name = match path.strip_prefix(root) {
        Ok(rel) if !root.as_os_str().is_empty() => rel.to_path_buf(),
        _ => std::path::absolute(path)
            .with_context(|| format!("cannot make {} absolute", path.display()))?,
    };
    let im = CocoImage {
        id,
        file_name: file_name.to_string_lossy().into_owned(),
        width,
        height,
        extra: Map::new(),
    };
    Ok((im, lines))
}

/// The lines of label file `file` (its text `text`) for a dataset of `classes` classes.
pub fn parse_labels(text: &str, file: &Path, classes: usize) -> Result<Vec<LabelLine>> {
    let mut out: Vec<LabelLine> = Vec::new();
    let mut duplicates = 0;
    for (ln, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let l = parse_line(line, classes)
            .with_context(|| format!("{}:{}: {:?}", file.display(), ln + 1, clip(line)))?;
        if out.contains(&l) {
            duplicates += 1;
        } else {
            out.push(l);
        }
    }
    if duplicates > 0 {
        eprintln!(
            "warning: {}: {duplicates} duplicate label lines removed",
            file.display()
        );
    }
    Ok(out)
}

/// A line as an error quotes it: at most 60 characters.
fn clip(line: &str) -> String {
    match line.char_indices().nth(60) {
        Some((i, _)) => format!("{}…", &line[..i]),
        None => line.to_string(),
    }
}

fn parse_line(line: &str, classes: usize) -> Result<LabelLine> {
    let mut tokens = line.split_whitespace();
    let first = tokens.next().unwrap_or_default();
    let class = match first.parse::<f64>() {
        Ok(c) if c >= 0.0 && c.fract() == 0.0 && c < classes as f64 => c as usize,
        Ok(c) if c >= 0.0 && c.fract() == 0.0 => bail!(
            "class id {first} is out of range: data.yaml names {classes} class{} (ids 0..{})",
            if classes == 1 { "" } else { "es" },
            classes.saturating_sub(1)
        ),
        _ => bail!("class id {first:?} is not a whole number ≥ 0"),
    };
    let mut coords = Vec::new();
    for t in tokens {
        let v: f64 = t
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .with_context(|| format!("coordinate {t:?} is not a number"))?;
        if !(-TOLERANCE..=1.0 + TOLERANCE).contains(&v) {
            bail!("coordinate {t} is outside [0, 1]: YOLO labels are normalised by the image's width and height");
        }
        coords.push(v.clamp(0.0, 1.0));
    }
    if coords.len() == 4 {
        bail!("is a box (class x y w h); a YOLO-seg label needs a polygon of at least 3 points");
    }
    if coords.len() % 2 != 0 {
        bail!(
            "has an odd number of coordinates ({}); a polygon is x y pairs",
            coords.len()
        );
    }
    if coords.len() < 6 {
        bail!(
            "has {} point(s); a polygon needs at least 3",
            coords.len() / 2
        );
    }
    Ok(LabelLine {
        class,
        points: coords.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        format!(
            "{:#}",
            parse_labels(text, Path::new("ds/labels/a.txt"), 2).unwrap_err()
        )
    }

    #[test]
    fn label_lines_as_ultralytics_writes_them() {
        let l = parse_labels(
            "0 0.1 0.2 0.6 0.2 0.6 0.8\n\n1 0 0 1 0 1.005 1 -0.004 1\n0 0.1 0.2 0.6 0.2 0.6 0.8\n",
            Path::new("a.txt"),
            2,
        )
        .unwrap();
        assert_eq!(l.len(), 2, "blank line skipped, duplicate dropped");
        assert_eq!(l[0].class, 0);
        assert_eq!(l[0].points, [[0.1, 0.2], [0.6, 0.2], [0.6, 0.8]]);
        // Within the tolerance: clamped into the image.
        assert_eq!(
            l[1].points,
            [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
        );
        assert!(parse_labels("", Path::new("a.txt"), 2).unwrap().is_empty());
    }

    #[test]
    fn malformed_lines_name_file_and_line() {
        for (text, needle) in [
            ("0 0.1 0.2 0.6 0.2 0.6\n", "odd number of coordinates (5)"),
            ("0 0.1 0.2 0.6 0.2\n", "is a box"),
            ("0 0.1 0.2\n", "has 1 point(s)"),
            ("0\n", "has 0 point(s)"),
            (
                "0 0.1 0.2 x 0.2 0.6 0.8\n",
                "coordinate \"x\" is not a number",
            ),
            ("0 0.1 0.2 nan 0.2 0.6 0.8\n", "is not a number"),
            ("2 0.1 0.2 0.6 0.2 0.6 0.8\n", "class id 2 is out of range"),
            ("-1 0.1 0.2 0.6 0.2 0.6 0.8\n", "not a whole number"),
            ("0.5 0.1 0.2 0.6 0.2 0.6 0.8\n", "not a whole number"),
            ("car 0.1 0.2 0.6 0.2 0.6 0.8\n", "not a whole number"),
            (
                "0 0.1 0.2 1.2 0.2 0.6 0.8\n",
                "coordinate 1.2 is outside [0, 1]",
            ),
            ("0 0.1 -0.5 0.6 0.2 0.6 0.8\n", "outside [0, 1]"),
        ] {
            // On line 2, after a good line: the error says which.
            let e = err(&format!("0 0.1 0.2 0.6 0.2 0.6 0.8\n{text}"));
            assert!(e.contains("ds/labels/a.txt:2"), "{text:?}: {e}");
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn label_path_replaces_the_last_images_folder() {
        for (img, want) in [
            ("ds/images/train/a.jpg", "ds/labels/train/a.txt"),
            ("/d/images/x/images/b.PNG", "/d/images/x/labels/b.txt"),
            ("images/c.jpeg", "labels/c.txt"),
            ("flat/d.png", "flat/d.txt"),
            ("ds/images/images.jpg", "ds/labels/images.txt"),
        ] {
            assert_eq!(label_path(Path::new(img)), Path::new(want), "{img}");
        }
    }
}
