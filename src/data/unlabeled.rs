//! The unlabeled photos of self-training (`[data.unlabeled]`) and their pseudo-labels.
//!
//! [`UnlabeledSet::scan`] lists every `.jpg`, `.jpeg` and `.png` under the folder
//! (recursively, following links, sorted by path, hidden files and folders left out;
//! anything else there, label files included, is ignored) and reads each one's header,
//! so an empty folder or an unreadable image stops the run before step 1 with the file's
//! path. Images are decoded lazily, one per request, and letterboxed to the network input
//! like the real set's.
//!
//! The pseudo-labels ([`PseudoLabels`]) are made by the trainer (`train::self_training`,
//! which runs the teacher); here they are only data: per image, instances as masks at
//! the network input size, kept cropped to their boxes so hundreds of images fit in
//! memory. An image joins the training pool only with at least one pseudo-instance: an
//! image whose carcasses the teacher missed would otherwise teach "nothing here".

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use image::RgbImage;

use crate::annotations::image_file::{image_dimensions, read_image};
use crate::annotations::mask::CroppedMask;
use crate::data::dataset::{Instance, Sample};
use crate::data::letterbox::Letterbox;

/// The unlabeled images: their paths (sorted) and sizes.
#[derive(Clone, Debug)]
pub struct UnlabeledSet {
    pub root: PathBuf,
    pub paths: Vec<PathBuf>,
    /// `(width, height)` of each image (after its EXIF orientation).
    pub sizes: Vec<(u32, u32)>,
}

fn is_image(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
}

impl UnlabeledSet {
    /// Every image under `root` (see the module doc); errors name the folder or file.
    pub fn scan(root: &Path) -> Result<UnlabeledSet> {
        if !root.is_dir() {
            bail!(
                "data.unlabeled.images = {:?} is not a folder",
                root.display().to_string()
            );
        }
        let hidden = |e: &walkdir::DirEntry| {
            e.depth() > 0 && e.file_name().to_string_lossy().starts_with('.')
        };
        let mut paths = Vec::new();
        for e in walkdir::WalkDir::new(root)
            .follow_links(true)
            .sort_by_file_name()
            .into_iter()
            .filter_entry(|e| !hidden(e))
        {
            let e = e.with_context(|| format!("cannot read folder {}", root.display()))?;
            if e.file_type().is_file() && is_image(e.path()) {
                paths.push(e.into_path());
            }
        }
        paths.sort();
        if paths.is_empty() {
            bail!(
                "data.unlabeled.images = {:?} holds no .jpg/.jpeg/.png image (searched recursively)",
                root.display().to_string()
            );
        }
        let sizes = paths
            .iter()
            .map(|p| {
                image_dimensions(p).with_context(|| {
                    format!("data.unlabeled: cannot read the image {}", p.display())
                })
            })
            .collect::<Result<Vec<_>>>()?;
        if let Some(k) = sizes.iter().position(|&(w, h)| w == 0 || h == 0) {
            bail!(
                "data.unlabeled: the image {} is empty ({}x{})",
                paths[k].display(),
                sizes[k].0,
                sizes[k].1
            );
        }
        Ok(UnlabeledSet {
            root: root.to_path_buf(),
            paths,
            sizes,
        })
    }

    pub fn len(&self) -> usize {
        self.paths.len()
    }

    pub fn is_empty(&self) -> bool {
        self.paths.is_empty()
    }

    /// Image `k` letterboxed to `input × input`.
    pub fn image(&self, k: usize, input: u32) -> Result<RgbImage> {
        let p = &self.paths[k];
        let img = read_image(p)
            .with_context(|| format!("data.unlabeled: cannot read the image {}", p.display()))?;
        Ok(Letterbox::new(img.dimensions(), input).image(&img))
    }
}

/// One pseudo-instance: class index and mask at the network input size.
#[derive(Clone, Debug, PartialEq)]
pub struct PseudoInstance {
    pub class: usize,
    pub score: f32,
    pub mask: CroppedMask,
}

/// The pseudo-labels of an [`UnlabeledSet`] at one input size, and the images that train.
#[derive(Clone, Debug)]
pub struct PseudoLabels {
    pub set: UnlabeledSet,
    /// Network input size the masks are at.
    pub input: u32,
    /// Per image of `set`, in its order.
    pub labels: Vec<Vec<PseudoInstance>>,
    /// Epoch (0-based) before which they were made.
    pub made_before_epoch: usize,
    /// The score threshold they were kept at.
    pub threshold: f64,
}

impl PseudoLabels {
    /// The images with at least one pseudo-instance (indices into `set`): the pool
    /// batches draw from.
    pub fn pool(&self) -> Vec<u64> {
        (0..self.labels.len())
            .filter(|&k| !self.labels[k].is_empty())
            .map(|k| k as u64)
            .collect()
    }

    /// Pseudo-instances over all images.
    pub fn instances(&self) -> usize {
        self.labels.iter().map(Vec::len).sum()
    }

    /// Image `k` letterboxed, with its pseudo-instances as the sample's instances.
    pub fn sample(&self, k: u64) -> Result<Sample> {
        let k = k as usize;
        let Some(labels) = self.labels.get(k) else {
            bail!(
                "pseudo-labelled image {k} does not exist ({} images)",
                self.labels.len()
            );
        };
        let image = self.set.image(k, self.input)?;
        let instances = labels
            .iter()
            .filter(|p| p.mask.width == self.input && p.mask.height == self.input)
            .map(|p| Instance {
                class: p.class,
                mask: p.mask.full(),
            })
            .filter(|i| i.mask.area() > 0)
            .collect();
        Ok(Sample { image, instances })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotations::mask::Mask;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ct-unlabeled-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write_png(p: &Path, w: u32, h: u32) {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 7]))
            .save(p)
            .unwrap();
    }

    #[test]
    fn scan_finds_images_recursively_sorted_and_ignores_the_rest() {
        let d = tmp("scan");
        write_png(&d.join("b.png"), 8, 6);
        write_png(&d.join("sub/a.PNG"), 4, 4);
        write_png(&d.join("a.jpg.png"), 5, 5);
        write_png(&d.join(".hidden/c.png"), 4, 4);
        std::fs::write(d.join("b.txt"), "0 0.1 0.1 0.2 0.2 0.3 0.1").unwrap();
        std::fs::write(d.join("labels.json"), "{}").unwrap();
        let s = UnlabeledSet::scan(&d).unwrap();
        let names: Vec<String> = s
            .paths
            .iter()
            .map(|p| p.strip_prefix(&d).unwrap().display().to_string())
            .collect();
        assert_eq!(names, ["a.jpg.png", "b.png", "sub/a.PNG"]);
        assert_eq!(s.sizes, [(5, 5), (8, 6), (4, 4)]);
        // Letterboxed to the input: 8x6 into 16 keeps the aspect, padded.
        assert_eq!(s.image(1, 16).unwrap().dimensions(), (16, 16));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn an_empty_folder_or_a_broken_image_is_a_clear_error() {
        let d = tmp("bad");
        std::fs::write(d.join("notes.txt"), "no images here").unwrap();
        let e = format!("{:#}", UnlabeledSet::scan(&d).unwrap_err());
        assert!(e.contains("holds no .jpg/.jpeg/.png image"), "{e}");
        std::fs::write(d.join("broken.jpg"), b"not a jpeg").unwrap();
        let e = format!("{:#}", UnlabeledSet::scan(&d).unwrap_err());
        assert!(e.contains("broken.jpg"), "{e}");
        let e = format!("{:#}", UnlabeledSet::scan(&d.join("missing")).unwrap_err());
        assert!(e.contains("is not a folder"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn samples_carry_the_pseudo_instances_and_the_pool_skips_unlabelled_images() {
        let d = tmp("sample");
        write_png(&d.join("a.png"), 16, 16);
        write_png(&d.join("b.png"), 16, 16);
        let set = UnlabeledSet::scan(&d).unwrap();
        let mut m = Mask::new(16, 16);
        for y in 2..6 {
            for x in 3..9 {
                m.set(x, y, true);
            }
        }
        let mut on = Mask::new(4, 6);
        on.data.fill(1);
        let window = CroppedMask {
            width: 16,
            height: 16,
            x0: 3,
            y0: 2,
            window: on,
        };
        let labels = PseudoLabels {
            set,
            input: 16,
            labels: vec![
                vec![],
                vec![PseudoInstance {
                    class: 0,
                    score: 0.9,
                    mask: window,
                }],
            ],
            made_before_epoch: 3,
            threshold: 0.5,
        };
        assert_eq!(labels.pool(), [1]);
        assert_eq!(labels.instances(), 1);
        let s = labels.sample(1).unwrap();
        assert_eq!(s.image.dimensions(), (16, 16));
        assert_eq!(s.instances.len(), 1);
        assert_eq!(s.instances[0].mask, m);
        assert!(labels.sample(0).unwrap().instances.is_empty());
        assert!(labels.sample(2).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
