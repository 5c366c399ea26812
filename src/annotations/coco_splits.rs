//! COCO datasets that come split: one instances file per split (detectron2 registers
//! `coco_2017_train` and `coco_2017_val` as two files; Roboflow exports
//! `train/_annotations.coco.json`, `valid/…`, `test/…`), merged into one ground truth plus
//! the split the files declare ([`OwnSplit`]).
//!
//! Image and annotation ids are renumbered (each file counts from 1), in file order and
//! then each file's image order. Every file must have the same categories (ids and
//! names), or class indices would mean different things per split. An image's
//! `file_name` becomes its images folder joined with it, so one merged set can read
//! files from several folders.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::coco::CocoDataset;
use super::split::{OwnSplit, Part};

/// One split's file: which part, the instances file, the folder its `file_name`s are
/// relative to.
#[derive(Clone, Debug)]
pub struct SplitFile {
    pub part: Part,
    pub annotations: PathBuf,
    pub images: PathBuf,
}

/// Loads and merges `files`; image `file_name`s in the result include their folder.
pub fn load(files: &[SplitFile]) -> Result<(CocoDataset, OwnSplit)> {
    let mut loaded = Vec::with_capacity(files.len());
    for f in files {
        let ds = CocoDataset::load(&f.annotations)?;
        ds.validate()
            .with_context(|| format!("in {}", f.annotations.display()))?;
        loaded.push(ds);
    }
    merge(files, loaded)
}

/// [`load`] on already-read datasets (`loaded[i]` is `files[i]`'s).
pub fn merge(files: &[SplitFile], loaded: Vec<CocoDataset>) -> Result<(CocoDataset, OwnSplit)> {
    let mut out = CocoDataset::default();
    let mut own = OwnSplit::default();
    for (i, (f, ds)) in files.iter().zip(loaded).enumerate() {
        if i == 0 {
            out.categories = ds.categories.clone();
        } else if ds.sorted_categories() != out.sorted_categories() {
            bail!(
                "the categories of {} {:?} differ from those of {} {:?}: every split must have the same (id, name) pairs",
                f.annotations.display(),
                ds.sorted_categories(),
                files[0].annotations.display(),
                out.sorted_categories()
            );
        }
        let first_id = out.images.len() as u64 + 1;
        let mut new_id = std::collections::HashMap::with_capacity(ds.images.len());
        for (k, mut im) in ds.images.into_iter().enumerate() {
            let id = first_id + k as u64;
            new_id.insert(im.id, id);
            im.id = id;
            im.file_name = join(&f.images, &im.file_name);
            own.push(f.part, id);
            out.images.push(im);
        }
        for mut a in ds.annotations {
            a.image_id = *new_id.get(&a.image_id).with_context(|| {
                format!(
                    "{}: annotation {} refers to image {}, which is not in the file",
                    f.annotations.display(),
                    a.id,
                    a.image_id
                )
            })?;
            a.id = out.annotations.len() as u64 + 1;
            out.annotations.push(a);
        }
    }
    Ok((out, own))
}

/// Which split a COCO file holds, by its name: the file stem without `instances_`
/// (ultralytics' `convert_coco` names label folders so: `instances_val2017.json` →
/// `val2017`), else its folder's name (Roboflow's `valid/_annotations.coco.json`),
/// starting with `train`, `val` (`valid`, `validation`) or `test`.
pub fn part_of_file(file: &Path) -> Result<Part> {
    let stem = file
        .file_stem()
        .map(|s| s.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let stem = stem.strip_prefix("instances_").unwrap_or(&stem).to_string();
    let folder = file
        .parent()
        .and_then(|p| p.file_name())
        .map(|s| s.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    for name in [stem, folder] {
        for (prefix, part) in [
            ("train", Part::Train),
            ("val", Part::Val),
            ("test", Part::Test),
        ] {
            if name.starts_with(prefix) {
                return Ok(part);
            }
        }
    }
    bail!(
        "cannot tell which split {} holds: name it for its split (train.json, instances_val2017.json, …) or put it in a folder so named (train/, valid/, test/)",
        file.display()
    )
}

fn join(dir: &Path, file_name: &str) -> String {
    dir.join(file_name).to_string_lossy().into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ds(json: &str) -> CocoDataset {
        CocoDataset::from_json(json).unwrap()
    }

    fn file(part: Part, name: &str) -> SplitFile {
        SplitFile {
            part,
            annotations: PathBuf::from(format!("{name}.json")),
            images: PathBuf::from(name),
        }
    }

    const CATS: &str = r#""categories": [{"id": 3, "name": "carcass"}]"#;

    #[test]
    fn merges_renumbering_ids_and_keeps_each_files_split() {
        let ann = |id: u64, img: u64| {
            format!(
                r#"{{"id": {id}, "image_id": {img}, "category_id": 3, "segmentation": [[1, 1, 5, 1, 5, 5]], "area": 8, "bbox": [1, 1, 4, 4], "iscrowd": 0}}"#
            )
        };
        let a = ds(&format!(
            r#"{{"images": [{{"id": 7, "file_name": "a.jpg", "width": 8, "height": 8}}, {{"id": 9, "file_name": "b.jpg", "width": 8, "height": 8}}], "annotations": [{}, {}], {CATS}}}"#,
            ann(1, 9),
            ann(2, 7)
        ));
        let b = ds(&format!(
            r#"{{"images": [{{"id": 7, "file_name": "c.jpg", "width": 8, "height": 8}}], "annotations": [{}], {CATS}}}"#,
            ann(1, 7)
        ));
        let files = [file(Part::Train, "tr"), file(Part::Test, "te")];
        let (m, own) = merge(&files, vec![a, b]).unwrap();
        m.validate().unwrap();
        assert_eq!(own.train, [1, 2]);
        assert!(own.val.is_empty());
        assert_eq!(own.test, [3]);
        let names: Vec<&str> = m.images.iter().map(|i| i.file_name.as_str()).collect();
        assert_eq!(names, ["tr/a.jpg", "tr/b.jpg", "te/c.jpg"]);
        let pairs: Vec<(u64, u64)> = m.annotations.iter().map(|a| (a.id, a.image_id)).collect();
        assert_eq!(pairs, [(1, 2), (2, 1), (3, 3)]);
    }

    #[test]
    fn a_files_split_comes_from_its_name_or_folder() {
        for (f, want) in [
            ("ann/instances_train2017.json", Part::Train),
            ("val.json", Part::Val),
            ("rf/valid/_annotations.coco.json", Part::Val),
            ("rf/test/_annotations.coco.json", Part::Test),
            ("x/Validation.json", Part::Val),
        ] {
            assert_eq!(part_of_file(Path::new(f)).unwrap(), want, "{f}");
        }
        let e = part_of_file(Path::new("d/all.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("d/all.json"), "{e}");
    }

    #[test]
    fn different_categories_are_an_error_naming_both_files() {
        let a = ds(&format!(r#"{{"images": [], {CATS}}}"#));
        let b = ds(r#"{"images": [], "categories": [{"id": 3, "name": "wing"}]}"#);
        let files = [file(Part::Train, "tr"), file(Part::Val, "va")];
        let e = merge(&files, vec![a, b]).unwrap_err().to_string();
        assert!(e.contains("va.json") && e.contains("tr.json"), "{e}");
    }
}
