//! Training augmentation, composed as a list ([`Compose`], as ultralytics' `Compose` and
//! detectron2's `AugmentationList`): each augmentation a type with one `apply`
//! ([`Augment`]), run in the list's order. [`pipeline`] is the list of an
//! [`AugmentConfig`]; adding an augmentation is its file and its line there.
//!
//! The list, in ultralytics' order: [`CopyPaste`] ([`super::copy_paste`]) → [`Mosaic`]
//! ([`super::mosaic`]) → [`RandomAffine`] (rotation by up to `degrees`, scale `1 ± scale`
//! and `translate` as one warp, [`super::affine`]) → [`Crop`] (the paper's random
//! `crop × crop` window) → [`FlipLr`] (probability `fliplr`) → [`Hsv`] (ultralytics' HSV
//! gains drawn uniformly in `1 ± hsv[k]`, like `augment_hsv`) → [`FlipUd`] (`flipud`).
//! Each off at 0 but crop, the horizontal flip and HSV, which are the paper's. That is the
//! default order ([`crate::config::AUGMENTATIONS`]); `train.augment_order` runs the same
//! list in another ([`AugmentConfig::order`]).
//!
//! Crop, horizontal flip and HSV draw from the caller's item RNG exactly as before the
//! other augmentations existed; those draw from a second stream ([`augment_full`]'s
//! `extra`), so a config with them all 0 trains bit for bit as it did. Instances that
//! leave the crop are dropped; after a warp, mosaic or paste, those under
//! [`MIN_INSTANCE_PX`] pixels too.

pub mod crop;
pub mod flip;
pub mod hsv;
#[cfg(test)]
mod reference;
pub mod step;

use std::borrow::Cow;

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::affine::RandomAffine;
use super::copy_paste::CopyPaste;
use super::dataset::Sample;
use super::mosaic::Mosaic;
use crate::config::AUGMENTATIONS;
pub use crop::Crop;
pub use flip::{flip_horizontal, flip_vertical, FlipLr, FlipUd};
pub use hsv::{hsv_jitter, hsv_to_rgb, rgb_to_hsv, Hsv};
pub use step::{Augment, AugmentState, PartnerSamples, MIN_INSTANCE_PX};

/// What to apply (the `[train]` keys of the same names; `crop` is `data.crop`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AugmentConfig {
    pub crop: u32,
    pub fliplr: f64,
    pub hsv: [f64; 3],
    /// Rotation uniform in ±`degrees`.
    pub degrees: f64,
    /// Scale uniform in `1 ± scale`.
    pub scale: f64,
    /// Shift uniform in ±`translate` of the image size, per axis.
    pub translate: f64,
    /// Vertical flip probability.
    pub flipud: f64,
    /// Probability of a 2×2 mosaic with three other items of the epoch.
    pub mosaic: f64,
    /// Probability of pasting instances of another item of the epoch.
    pub copy_paste: f64,
    /// The order of the list: positions in [`AUGMENTATIONS`] (`train.augment_order`,
    /// validated by the config to be a permutation; [`DEFAULT_ORDER`] unless set).
    pub order: [usize; AUGMENTATIONS.len()],
}

/// The list in [`AUGMENTATIONS`]' own order.
pub const DEFAULT_ORDER: [usize; AUGMENTATIONS.len()] = [0, 1, 2, 3, 4, 5, 6];

impl AugmentConfig {
    /// Crop, flip and colour jitter only (every other augmentation off).
    pub fn basic(crop: u32, fliplr: f64, hsv: [f64; 3]) -> AugmentConfig {
        AugmentConfig {
            crop,
            fliplr,
            hsv,
            degrees: 0.0,
            scale: 0.0,
            translate: 0.0,
            flipud: 0.0,
            mosaic: 0.0,
            copy_paste: 0.0,
            order: DEFAULT_ORDER,
        }
    }

    /// Whether anything beyond crop, horizontal flip and HSV is on.
    pub fn extended(&self) -> bool {
        self.warps() || self.flipud > 0.0 || self.copy_paste > 0.0
    }

    /// Whether the affine warp can be other than the identity.
    pub fn warps(&self) -> bool {
        self.degrees > 0.0 || self.scale > 0.0 || self.translate > 0.0 || self.mosaic > 0.0
    }
}

/// The other items of the epoch (positions in its plan) that one item's augmentation
/// reads: drawn from the item's `extra` stream, so they depend only on the item's key.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Partners {
    pub copy_paste: Option<usize>,
    /// Up to three positions (fewer when the plan is shorter): the mosaic's other tiles.
    pub mosaic: Option<Vec<usize>>,
}

/// `k` distinct positions of `0..len` other than `pos` (all of them when fewer exist).
fn others<R: Rng>(rng: &mut R, pos: usize, len: usize, k: usize) -> Vec<usize> {
    let n = len.saturating_sub(1);
    rand::seq::index::sample(rng, n, k.min(n))
        .into_iter()
        .map(|i| if i >= pos { i + 1 } else { i })
        .collect()
}

/// Whether copy-paste and mosaic apply to the item at `pos` of a `len`-item plan, and
/// with which partners. Draws nothing for an augmentation that is off.
pub fn draw_partners<R: Rng>(
    cfg: &AugmentConfig,
    extra: &mut R,
    pos: usize,
    len: usize,
) -> Partners {
    let mut p = Partners::default();
    if cfg.copy_paste > 0.0 && extra.random::<f64>() < cfg.copy_paste {
        p.copy_paste = others(extra, pos, len, 1).first().copied();
    }
    if cfg.mosaic > 0.0 && extra.random::<f64>() < cfg.mosaic {
        p.mosaic = Some(others(extra, pos, len, 3));
    }
    p
}

/// Augmentations run in order on one item ([`Compose::apply`]).
pub struct Compose(pub Vec<Box<dyn Augment>>);

impl Compose {
    /// The names of the augmentations, in order.
    pub fn names(&self) -> Vec<&'static str> {
        self.0.iter().map(|a| a.name()).collect()
    }

    /// `s` through every augmentation of the list, in order.
    pub fn apply(&self, s: &Sample, st: &mut AugmentState) -> Sample {
        let mut cur = Cow::Borrowed(s);
        for a in &self.0 {
            cur = a.apply(cur, st);
        }
        cur.into_owned()
    }
}

/// The augmentation list of `cfg`: every augmentation, in `cfg.order` (one that is off
/// does nothing and draws nothing, but crop, the horizontal flip and HSV, whose draws the
/// main stream always had).
pub fn pipeline(cfg: &AugmentConfig) -> Compose {
    // In the order of `AUGMENTATIONS`, whose names are theirs (a test checks it).
    let steps: [Box<dyn Augment>; AUGMENTATIONS.len()] = [
        Box::new(CopyPaste),
        Box::new(Mosaic),
        Box::new(RandomAffine {
            degrees: cfg.degrees,
            scale: cfg.scale,
            translate: cfg.translate,
            on: cfg.warps(),
        }),
        Box::new(Crop {
            size: cfg.crop,
            drop_slivers: cfg.extended(),
        }),
        Box::new(FlipLr { p: cfg.fliplr }),
        Box::new(Hsv { gains: cfg.hsv }),
        Box::new(FlipUd { p: cfg.flipud }),
    ];
    let mut steps = steps.map(Some);
    Compose(
        cfg.order
            .iter()
            .map(|&i| {
                steps[i]
                    .take()
                    .expect("AugmentConfig::order is a permutation (the config checks it)")
            })
            .collect(),
    )
}

/// The whole pipeline: copy-paste from `partners.copy_paste`, a mosaic with
/// `partners.mosaic`, the affine warp and the vertical flip draw from `extra`; crop,
/// horizontal flip and HSV from `rng`.
pub fn augment_full<R: Rng, E: Rng>(
    s: &Sample,
    partners: &PartnerSamples,
    cfg: &AugmentConfig,
    extra: &mut E,
    rng: &mut R,
) -> Sample {
    let mut st = AugmentState {
        rng: rng as &mut dyn RngCore,
        extra: extra as &mut dyn RngCore,
        partners,
        canvas: None,
    };
    pipeline(cfg).apply(s, &mut st)
}

/// Crop, flip and colour-jitter one sample: the pipeline of a config with nothing else
/// on, which draws only from `rng` (what the loader runs then, without a second stream).
pub fn augment<R: Rng>(s: &Sample, cfg: &AugmentConfig, rng: &mut R) -> Sample {
    // Nothing of the basic list draws from the second stream: a fixed one stands in.
    let mut unused = ChaCha8Rng::seed_from_u64(0);
    let basic = AugmentConfig {
        order: cfg.order,
        ..AugmentConfig::basic(cfg.crop, cfg.fliplr, cfg.hsv)
    };
    augment_full(s, &PartnerSamples::default(), &basic, &mut unused, rng)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotations::mask::Mask;
    use crate::data::dataset::Instance;
    use image::RgbImage;

    fn sample() -> Sample {
        let mut image = RgbImage::new(8, 8);
        for (x, y, p) in image.enumerate_pixels_mut() {
            p.0 = [(x * 30) as u8, (y * 30) as u8, 100];
        }
        let mut m = Mask::new(8, 8);
        m.set(0, 0, true);
        m.set(1, 0, true);
        let mut far = Mask::new(8, 8);
        far.set(7, 7, true);
        Sample {
            image,
            instances: vec![
                Instance { class: 0, mask: m },
                Instance {
                    class: 1,
                    mask: far,
                },
            ],
        }
    }

    #[test]
    fn hsv_round_trip() {
        for rgb in [
            [0.2f32, 0.5, 0.9],
            [1.0, 0.0, 0.0],
            [0.3, 0.3, 0.3],
            [0.9, 0.8, 0.1],
        ] {
            let (h, s, v) = rgb_to_hsv(rgb[0], rgb[1], rgb[2]);
            let (r, g, b) = hsv_to_rgb(h, s, v);
            assert!(
                (r - rgb[0]).abs() < 1e-5 && (g - rgb[1]).abs() < 1e-5 && (b - rgb[2]).abs() < 1e-5
            );
        }
    }

    #[test]
    fn flip_only_mirrors_image_and_masks() {
        let s = sample();
        let cfg = AugmentConfig::basic(8, 1.0, [0.0; 3]);
        let a = augment(&s, &cfg, &mut ChaCha8Rng::seed_from_u64(1));
        assert_eq!(a.image.get_pixel(7, 3), s.image.get_pixel(0, 3));
        assert!(a.instances[0].mask.get(7, 0) && a.instances[0].mask.get(6, 0));
        assert_eq!(a.instances[0].mask.area(), 2);
    }

    #[test]
    fn crop_drops_instances_outside_and_is_seeded() {
        let s = sample();
        let cfg = AugmentConfig::basic(4, 0.0, [0.015, 0.7, 0.4]);
        let mut kept = [0usize; 3];
        for seed in 0..40 {
            let a = augment(&s, &cfg, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!(a.image.dimensions(), (4, 4));
            kept[a.instances.len()] += 1;
            let b = augment(&s, &cfg, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!(a.image, b.image);
            for i in &a.instances {
                assert_eq!((i.mask.width, i.mask.height), (4, 4));
            }
        }
        // The two instances sit in opposite corners of 8×8: a 4×4 crop never holds both.
        assert_eq!(kept[2], 0);
        assert!(kept[1] > 0 && kept[0] > 0, "{kept:?}");
    }

    /// A `size²` sample on background `bg` with one instance per rectangle
    /// `(x0, y0, x1, y1)`, painted in its own grey level `c0 + 20 k` (class = colour).
    fn painted(size: u32, bg: u8, c0: u8, rects: &[(u32, u32, u32, u32)]) -> Sample {
        let mut image = RgbImage::from_pixel(size, size, image::Rgb([bg, 0, 0]));
        let mut instances = Vec::new();
        for (k, &(x0, y0, x1, y1)) in rects.iter().enumerate() {
            let c = c0 + 20 * k as u8;
            let mut m = Mask::new(size, size);
            for y in y0..y1 {
                for x in x0..x1 {
                    m.set(x, y, true);
                    image.put_pixel(x, y, image::Rgb([c, 0, 0]));
                }
            }
            instances.push(Instance {
                class: c as usize,
                mask: m,
            });
        }
        Sample { image, instances }
    }

    /// Each instance's mask covers the pixels of its colour: pixels deep inside a mask
    /// (the `(2r + 1)²` neighbourhood in it) have exactly that colour, and pixels deep
    /// inside a region of that colour are in the mask; only an `r`-px rim may blend.
    /// `r = 1` holds for rectangles under rotation and flips (the bilinear taps lie
    /// within one pixel per axis), `r = 2` under upscaling by up to 1.3. Returns how many
    /// deep mask pixels it checked.
    fn assert_aligned(s: &Sample, what: &str, r: i64) -> usize {
        let (w, h) = s.image.dimensions();
        let deep = |f: &dyn Fn(u32, u32) -> bool, x: u32, y: u32| {
            (-r..=r).all(|dy| {
                (-r..=r).all(|dx| {
                    let (u, v) = (x as i64 + dx, y as i64 + dy);
                    u >= 0 && v >= 0 && u < w as i64 && v < h as i64 && f(u as u32, v as u32)
                })
            })
        };
        let mut inside = 0;
        for inst in &s.instances {
            let c = inst.class as u8;
            // Mosaic and copy-paste may bring in two copies of one sample's instance.
            let in_some = |u: u32, v: u32| {
                s.instances
                    .iter()
                    .any(|j| j.class == inst.class && j.mask.get(u, v))
            };

            for y in 0..h {
                for x in 0..w {
                    if deep(&|u, v| inst.mask.get(u, v), x, y) {
                        inside += 1;
                        assert_eq!(
                            s.image.get_pixel(x, y).0[0],
                            c,
                            "{what}: class {c} at ({x},{y})"
                        );
                    }
                    if deep(&|u, v| s.image.get_pixel(u, v).0 == [c, 0, 0], x, y) {
                        assert!(
                            in_some(x, y),
                            "{what}: colour {c} outside its mask at ({x},{y})"
                        );
                    }
                }
            }
        }
        inside
    }

    #[test]
    fn the_alignment_check_catches_a_shifted_mask() {
        let a = painted(32, 5, 30, &[(4, 4, 20, 20)]);
        assert!(assert_aligned(&a, "painted", 1) > 0);
        // Shifted by r + 1 pixels, the rim tolerance no longer covers it.
        for r in [1, 2] {
            let mut bad = a.clone();
            let m = &mut bad.instances[0].mask;
            *m = Mask::new(32, 32);
            for y in 4..20 {
                for x in 4 + r as u32 + 1..20 + r as u32 + 1 {
                    m.set(x, y, true);
                }
            }
            assert!(std::panic::catch_unwind(|| assert_aligned(&bad, "shifted", r)).is_err());
        }
    }

    fn full(crop: u32) -> AugmentConfig {
        AugmentConfig {
            degrees: 180.0,
            scale: 0.3,
            translate: 0.1,
            flipud: 0.5,
            mosaic: 1.0,
            copy_paste: 1.0,
            ..AugmentConfig::basic(crop, 0.5, [0.0; 3])
        }
    }

    #[test]
    fn every_augmentation_keeps_masks_on_their_pixels() {
        let a = painted(48, 5, 30, &[(4, 4, 16, 16), (18, 10, 40, 30)]);
        let b = painted(48, 6, 90, &[(10, 20, 30, 44)]);
        let c = painted(48, 7, 130, &[(0, 0, 24, 24)]);
        let d = painted(48, 8, 170, &[(30, 2, 46, 46)]);
        let mut kinds = [0usize; 4];
        let mut checked = 0;
        for seed in 0..12u64 {
            for (name, r, cfg) in [
                (
                    "rotate",
                    1,
                    AugmentConfig {
                        degrees: 180.0,
                        ..AugmentConfig::basic(48, 0.0, [0.0; 3])
                    },
                ),
                (
                    "scale+translate",
                    2,
                    AugmentConfig {
                        scale: 0.3,
                        translate: 0.2,
                        ..AugmentConfig::basic(40, 0.0, [0.0; 3])
                    },
                ),
                (
                    "flipud",
                    1,
                    AugmentConfig {
                        flipud: 1.0,
                        ..AugmentConfig::basic(48, 0.0, [0.0; 3])
                    },
                ),
                ("all", 2, full(40)),
            ] {
                let mut extra = ChaCha8Rng::seed_from_u64(seed ^ 0x77);
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let p = draw_partners(&cfg, &mut extra, 0, 4);
                let pool = [&a, &b, &c, &d];
                let ps = PartnerSamples {
                    copy_paste: p.copy_paste.map(|q| pool[q]),
                    mosaic: p
                        .mosaic
                        .as_ref()
                        .map(|qs| qs.iter().map(|&q| pool[q]).collect()),
                };
                let out = augment_full(&a, &ps, &cfg, &mut extra, &mut rng);
                assert_eq!(out.image.dimensions(), (cfg.crop, cfg.crop));
                checked += assert_aligned(&out, &format!("{name} seed {seed}"), r);
                for i in &out.instances {
                    assert!(i.mask.area() >= MIN_INSTANCE_PX);
                    kinds[[30, 50, 90, 130]
                        .iter()
                        .position(|&k| k == i.class)
                        .unwrap_or(3)] += 1;
                }
            }
        }
        // Mosaic and copy-paste bring other samples' instances in.
        assert!(kinds[2] > 0 && kinds[3] > 0, "{kinds:?}");
        assert!(checked > 10_000, "only {checked} mask pixels checked");
    }

    #[test]
    fn flipud_mirrors_rows_of_image_and_masks() {
        let a = painted(6, 0, 30, &[(1, 0, 3, 2)]);
        let mut f = a.clone();
        flip_vertical(&mut f);
        assert_eq!(f.image.get_pixel(1, 5), a.image.get_pixel(1, 0));
        assert!(f.instances[0].mask.get(2, 4) && !f.instances[0].mask.get(2, 1));
        flip_vertical(&mut f);
        assert_eq!((f.image, f.instances), (a.image, a.instances));
    }

    #[test]
    fn degenerate_inputs_give_valid_samples() {
        let cfg = full(32);
        let empty = painted(32, 5, 30, &[]);
        let one = painted(32, 5, 30, &[(2, 2, 12, 12)]);
        for seed in 0..8 {
            let mut extra = ChaCha8Rng::seed_from_u64(seed);
            let mut rng = ChaCha8Rng::seed_from_u64(seed + 100);
            // No instances anywhere; a one-item plan has no partners at all.
            let p = draw_partners(&cfg, &mut extra, 0, 1);
            assert_eq!(p.copy_paste, None);
            assert_eq!(p.mosaic, Some(vec![]));
            let ps = PartnerSamples {
                copy_paste: None,
                mosaic: Some(vec![]),
            };
            let out = augment_full(&empty, &ps, &cfg, &mut extra, &mut rng);
            assert_eq!(out.image.dimensions(), (32, 32));
            assert!(out.instances.is_empty());
            // A mosaic of two, copy-paste from a sample without instances.
            let ps = PartnerSamples {
                copy_paste: Some(&empty),
                mosaic: Some(vec![&one]),
            };
            let out = augment_full(&one, &ps, &cfg, &mut extra, &mut rng);
            assert_eq!(out.image.dimensions(), (32, 32));
            assert!(out.instances.len() <= 2);
            let _ = assert_aligned(&out, "two-tile mosaic", 2);
        }
        // Everything shifted out of the frame: no instances, a grey image.
        let cfg = AugmentConfig {
            translate: 0.99,
            ..AugmentConfig::basic(32, 0.0, [0.0; 3])
        };
        let mut left = 0;
        for seed in 0..40 {
            let out = augment_full(
                &one,
                &PartnerSamples::default(),
                &cfg,
                &mut ChaCha8Rng::seed_from_u64(seed),
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            left += out.instances.is_empty() as usize;
            let _ = assert_aligned(&out, "translated", 1);
        }
        assert!(left > 0);
    }

    #[test]
    fn the_pipeline_is_a_function_of_the_key_and_off_means_the_old_path() {
        let a = painted(32, 5, 30, &[(2, 2, 20, 12), (10, 14, 30, 30)]);
        let b = painted(32, 6, 90, &[(0, 0, 16, 16)]);
        let cfg = full(24);
        let run = |seed: u64| {
            let mut extra = ChaCha8Rng::seed_from_u64(seed ^ 1);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let p = draw_partners(&cfg, &mut extra, 2, 5);
            assert!(p.copy_paste != Some(2) && !p.mosaic.as_ref().unwrap().contains(&2));
            let ps = PartnerSamples {
                copy_paste: Some(&b),
                mosaic: Some(vec![&b, &a, &b]),
            };
            (p, augment_full(&a, &ps, &cfg, &mut extra, &mut rng))
        };
        let (p1, s1) = run(9);
        let (p2, s2) = run(9);
        assert_eq!(p1, p2);
        assert_eq!((s1.image, s1.instances), (s2.image, s2.instances));
        assert_ne!(run(10).1.image, run(9).1.image);
        // With every new key 0 the pipeline is `augment` on the same stream, and the
        // second stream is never read.
        let basic = AugmentConfig::basic(24, 0.5, [0.015, 0.7, 0.4]);
        assert!(!basic.extended());
        let mut extra = ChaCha8Rng::seed_from_u64(3);
        let before = extra.clone();
        let got = augment_full(
            &a,
            &PartnerSamples::default(),
            &basic,
            &mut extra,
            &mut ChaCha8Rng::seed_from_u64(4),
        );
        let want = augment(&a, &basic, &mut ChaCha8Rng::seed_from_u64(4));
        assert_eq!((got.image, got.instances), (want.image, want.instances));
        assert_eq!(extra, before);
    }

    #[test]
    fn the_list_runs_in_the_configured_order_under_the_configs_names() {
        let cfg = AugmentConfig::basic(24, 0.5, [0.015, 0.7, 0.4]);
        // HSV and the flip before the crop: the main stream's draws go to other steps.
        let reordered = AugmentConfig {
            order: [5, 4, 3, 0, 1, 2, 6],
            ..cfg
        };
        assert_eq!(
            pipeline(&reordered).names(),
            [
                "hsv",
                "fliplr",
                "crop",
                "copy_paste",
                "mosaic",
                "affine",
                "flipud"
            ]
        );
        let a = painted(32, 5, 30, &[(2, 2, 20, 12), (10, 14, 30, 30)]);
        let run = |c: &AugmentConfig| augment(&a, c, &mut ChaCha8Rng::seed_from_u64(7));
        let (x, y) = (run(&reordered), run(&reordered));
        assert_eq!(x.image, y.image);
        assert_eq!(x.instances, y.instances);
        assert_eq!(x.image.dimensions(), (24, 24));
        assert_ne!(x.image, run(&cfg).image);
    }
}
