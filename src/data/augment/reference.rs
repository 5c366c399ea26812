//! The augmentation pipeline as it was before it became a list (issue 40): one function
//! with every step inline, kept only as the reference the list must reproduce byte for
//! byte (`tests` in `super`), every random draw in the same order from the same streams.

use image::RgbImage;
use rand::Rng;

use super::flip::flip_vertical;
use super::hsv::hsv_jitter;
use super::step::{PartnerSamples, MIN_INSTANCE_PX};
use super::AugmentConfig;
use crate::annotations::mask::Mask;
use crate::data::affine::{warp, Affine};
use crate::data::copy_paste::copy_paste;
use crate::data::dataset::{Instance, Sample};
use crate::data::mosaic::mosaic;

/// The whole pipeline: copy-paste from `partners.copy_paste`, a mosaic with
/// `partners.mosaic`, the affine warp and the vertical flip draw from `extra`; crop,
/// horizontal flip and HSV from `rng` through [`augment`].
pub fn reference_full<R: Rng, E: Rng>(
    s: &Sample,
    partners: &PartnerSamples,
    cfg: &AugmentConfig,
    extra: &mut E,
    rng: &mut R,
) -> Sample {
    let pasted;
    let mut cur = s;
    if let Some(src) = partners.copy_paste {
        pasted = copy_paste(cur, src, extra, MIN_INSTANCE_PX);
        cur = &pasted;
    }
    let (w, h) = cur.image.dimensions();
    let tiled;
    let mut from = (w, h);
    if let Some(rest) = &partners.mosaic {
        let centre = (
            extra.random_range(w / 2..=w + w / 2),
            extra.random_range(h / 2..=h + h / 2),
        );
        let mut tiles = vec![cur];
        tiles.extend(rest.iter().copied());
        tiled = mosaic(&tiles, (w, h), centre, MIN_INSTANCE_PX);
        cur = &tiled;
        from = (2 * w, 2 * h);
    }
    let warped;
    if cfg.warps() {
        let degrees = if cfg.degrees > 0.0 {
            extra.random_range(-cfg.degrees..=cfg.degrees)
        } else {
            0.0
        };
        let scale = if cfg.scale > 0.0 {
            extra.random_range(1.0 - cfg.scale..=1.0 + cfg.scale)
        } else {
            1.0
        };
        let shift = if cfg.translate > 0.0 {
            (
                extra.random_range(-cfg.translate..=cfg.translate) * w as f64,
                extra.random_range(-cfg.translate..=cfg.translate) * h as f64,
            )
        } else {
            (0.0, 0.0)
        };
        let a = Affine::about_centre(from, (w, h), degrees, scale, shift);
        warped = warp(cur, &a, (w, h), MIN_INSTANCE_PX);
        cur = &warped;
    }
    let mut out = reference_basic(cur, cfg, rng);
    if cfg.extended() {
        // The crop cuts too; below the threshold it is a sliver, not a target.
        out.instances.retain(|i| i.mask.area() >= MIN_INSTANCE_PX);
    }
    if cfg.flipud > 0.0 && extra.random::<f64>() < cfg.flipud {
        flip_vertical(&mut out);
    }
    out
}

/// Crop, flip and colour-jitter one sample.
pub fn reference_basic<R: Rng>(s: &Sample, cfg: &AugmentConfig, rng: &mut R) -> Sample {
    let (w, h) = s.image.dimensions();
    let cw = cfg.crop.min(w);
    let ch = cfg.crop.min(h);
    let x0 = rng.random_range(0..=w - cw);
    let y0 = rng.random_range(0..=h - ch);
    let flip = rng.random::<f64>() < cfg.fliplr;
    let gains = [
        1.0 + cfg.hsv[0] * rng.random_range(-1.0..=1.0),
        1.0 + cfg.hsv[1] * rng.random_range(-1.0..=1.0),
        1.0 + cfg.hsv[2] * rng.random_range(-1.0..=1.0),
    ];
    let src_x = |x: u32| if flip { x0 + cw - 1 - x } else { x0 + x };
    let mut image = RgbImage::new(cw, ch);
    for y in 0..ch {
        for x in 0..cw {
            image.put_pixel(x, y, *s.image.get_pixel(src_x(x), y0 + y));
        }
    }
    if cfg.hsv.iter().any(|&g| g > 0.0) {
        hsv_jitter(&mut image, gains);
    }
    let instances = s
        .instances
        .iter()
        .filter_map(|inst| {
            let mut m = Mask::new(ch, cw);
            for y in 0..ch {
                let row = ((y0 + y) * inst.mask.width) as usize;
                for x in 0..cw {
                    m.data[(y * cw + x) as usize] = inst.mask.data[row + src_x(x) as usize];
                }
            }
            (m.area() > 0).then_some(Instance {
                class: inst.class,
                mask: m,
            })
        })
        .collect();
    Sample { image, instances }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::augment::{augment, augment_full, draw_partners, pipeline};
    use rand::{RngCore, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A `size²` sample with a colour gradient and one instance per rectangle.
    fn sample(size: u32, tint: u8, rects: &[(u32, u32, u32, u32)]) -> Sample {
        let mut image = RgbImage::new(size, size);
        for (x, y, p) in image.enumerate_pixels_mut() {
            p.0 = [(x * 7) as u8, (y * 5) as u8, tint];
        }
        let instances = rects
            .iter()
            .enumerate()
            .map(|(k, &(x0, y0, x1, y1))| {
                let mut m = Mask::new(size, size);
                for y in y0..y1 {
                    for x in x0..x1 {
                        m.set(x, y, true);
                    }
                }
                Instance { class: k, mask: m }
            })
            .collect();
        Sample { image, instances }
    }

    fn same(a: &Sample, b: &Sample, what: &str) {
        assert_eq!(a.image, b.image, "{what}: image");
        assert_eq!(a.instances, b.instances, "{what}: instances");
    }

    /// Every configuration of the pipeline, every seed: the list gives the pre-list
    /// pipeline's sample exactly and leaves both streams where it left them.
    #[test]
    fn the_list_reproduces_the_pre_list_pipeline_byte_for_byte() {
        let a = sample(40, 10, &[(2, 2, 14, 12), (20, 8, 38, 30), (0, 30, 6, 40)]);
        let b = sample(40, 60, &[(8, 18, 28, 36)]);
        let c = sample(40, 110, &[(0, 0, 20, 20), (30, 30, 40, 40)]);
        let d = sample(40, 160, &[]);
        let pool = [&a, &b, &c, &d];
        let basic = AugmentConfig::basic(32, 0.5, [0.015, 0.7, 0.4]);
        let configs = [
            ("basic", basic),
            ("no hsv", AugmentConfig::basic(40, 0.5, [0.0; 3])),
            (
                "rotate",
                AugmentConfig {
                    degrees: 30.0,
                    ..basic
                },
            ),
            (
                "scale+translate",
                AugmentConfig {
                    scale: 0.3,
                    translate: 0.2,
                    ..basic
                },
            ),
            (
                "flipud",
                AugmentConfig {
                    flipud: 0.5,
                    ..basic
                },
            ),
            (
                "mosaic",
                AugmentConfig {
                    mosaic: 0.7,
                    ..basic
                },
            ),
            (
                "copy_paste",
                AugmentConfig {
                    copy_paste: 0.7,
                    ..basic
                },
            ),
            (
                "all",
                AugmentConfig {
                    degrees: 180.0,
                    scale: 0.3,
                    translate: 0.1,
                    flipud: 0.5,
                    mosaic: 0.6,
                    copy_paste: 0.6,
                    ..basic
                },
            ),
        ];
        for (name, cfg) in configs {
            for seed in 0..24u64 {
                let what = format!("{name} seed {seed}");
                let run =
                    |f: &dyn Fn(&PartnerSamples, &mut ChaCha8Rng, &mut ChaCha8Rng) -> Sample| {
                        let mut extra = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
                        let mut rng = ChaCha8Rng::seed_from_u64(seed);
                        let p = draw_partners(&cfg, &mut extra, (seed % 4) as usize, 4);
                        let ps = PartnerSamples {
                            copy_paste: p.copy_paste.map(|q| pool[q]),
                            mosaic: p
                                .mosaic
                                .as_ref()
                                .map(|qs| qs.iter().map(|&q| pool[q]).collect()),
                        };
                        let out = f(&ps, &mut extra, &mut rng);
                        (out, extra.next_u64(), rng.next_u64())
                    };
                let s = pool[(seed % 4) as usize];
                let (want, we, wr) = run(&|ps, e, r| reference_full(s, ps, &cfg, e, r));
                let (got, ge, gr) = run(&|ps, e, r| augment_full(s, ps, &cfg, e, r));
                same(&got, &want, &what);
                assert_eq!((ge, gr), (we, wr), "{what}: the streams end where they did");
                if !cfg.extended() {
                    let mut r = ChaCha8Rng::seed_from_u64(seed);
                    let got = augment(s, &cfg, &mut r);
                    let want = reference_basic(s, &cfg, &mut ChaCha8Rng::seed_from_u64(seed));
                    same(&got, &want, &format!("{what}, basic"));
                }
            }
        }
    }

    /// Today's order, which the configs rely on for their draws, under the names
    /// `train.augment_order` takes.
    #[test]
    fn the_default_list_is_ultralytics_order() {
        let cfg = AugmentConfig::basic(32, 0.5, [0.0; 3]);
        let names = pipeline(&cfg).names();
        assert_eq!(
            names.join(" → "),
            "copy_paste → mosaic → affine → crop → fliplr → hsv → flipud"
        );
        assert_eq!(names, crate::config::AUGMENTATIONS);
    }
}
