//! chicktrain's built-in renderer: posed procedural carcasses piled on a steel plate,
//! ray traced with soft shadows, auto-labelled (visible + amodal masks, visib_fract) and
//! written as COCO, or read by the training loader through the render cache.
//!
//! Entry points:
//! * [`render_sample`]: sample `index` of dataset seed `seed`, deterministic.
//! * [`dataset::render_dataset`]: `images/`, `annotations.json`, `preview.png`,
//!   `render_meta.json`.
//! * [`bench::bench_render`]: images/s and the time split (scene, BVH build, trace,
//!   labels, sensor, encode).
//! * [`cache::load_or_render`]: one sample through the on-disk render cache.
//!
//! One concept per file: `carcass` (generator), `glb` (asset I/O), `asset` (the loaded
//! carcass asset), `mesh`, `skin` (poses), `pile` (heightfield drop), `camera`, `light`,
//! `surface` (what a material answers), `material` (skin, plate), `line_surface` (belt),
//! `prop_material` (distractors' look and ids), `distractor` (their meshes), `clutter`
//! (the negatives knob's dead-leaves pictures), `noise`,
//! `trace` (BVH rays + shading), `screen` (raster primary visibility, shadow filter,
//! crevices), `sensor`, `labels`, `scene` (sampling), `preset` (options), `export`
//! (COCO + preview), `dataset` (a dataset folder), `bench` (render timings), `cache`;
//! the carcass randomisation group: `family` (body families), `parts` (wings and legs
//! posed or cut), `variety` (per-carcass draws: family, size, parts, skin marks, tears).

pub mod asset;
pub mod bench;
pub mod cache;
pub mod camera;
pub mod carcass;
pub mod clutter;
pub mod dataset;
pub mod distractor;
pub mod export;
pub mod family;
pub mod glb;
pub mod labels;
pub mod lens;
pub mod light;
pub mod line_surface;
pub mod material;
pub mod mesh;
pub mod noise;
pub mod parts;
pub mod pile;
pub mod preset;
pub mod prop_material;
pub mod ranges;
pub mod scene;
pub mod screen;
pub mod sensor;
pub mod settle;
pub mod skin;
pub mod surface;
pub mod trace;
pub mod variety;

use std::time::{Duration, Instant};

use image::RgbImage;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::util::hash::mix64;
use crate::util::png::encode_png;

pub use labels::{InstanceLabel, LabelThresholds};
pub use preset::{ImageFormat, RenderOptions};

/// Bumped whenever output for a given (options, seed, index) changes; part of cache keys.
pub const RENDERER_VERSION: &str = "chicktrain-render-1";
/// Version of what the randomisation groups draw; part of the cache key of every render
/// with a group on (bump it when a group's ranges or sampling change).
pub const RANDOMIZE_VERSION: &str = "randomize-1";
/// Version of the clutter pictures ([`clutter`]); part of the cache key of every render
/// with a clutter share > 0 (bump it when what a clutter picture draws changes: a run of
/// 2026-12-08 trained a changed drawing on the old pictures from the cache).
pub const CLUTTER_VERSION: &str = "clutter-1";

/// Where the time of one image went.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Timings {
    /// Pose, skinning, pile drop, light/camera sampling.
    pub scene: Duration,
    /// The part of `scene` spent posing the carcasses and settling them with physics
    /// (physics group on; zero for the height-field drop, whose posing is in `scene` only).
    pub physics: Duration,
    pub build: Duration,
    pub trace: Duration,
    /// Amodal raster + label statistics.
    pub labels: Duration,
    /// Crevice darkening + sensor pipeline.
    pub sensor: Duration,
    /// File encoding (only filled by callers that encode).
    pub encode: Duration,
}

impl std::ops::AddAssign for Timings {
    fn add_assign(&mut self, o: Timings) {
        self.scene += o.scene;
        self.physics += o.physics;
        self.build += o.build;
        self.trace += o.trace;
        self.labels += o.labels;
        self.sensor += o.sensor;
        self.encode += o.encode;
    }
}

/// One rendered image with its labels.
#[derive(Clone, Debug)]
pub struct RenderedSample {
    pub image: RgbImage,
    /// First-hit instance ids, row-major, 0 = background; instance k's visible mask is
    /// exactly `ids == instances[k].id`.
    pub ids: Vec<u16>,
    /// Kept instances (fully hidden ones dropped; `ignore` marks too small/hidden ones).
    pub instances: Vec<InstanceLabel>,
    /// JPEG quality this image should be saved at (part of the sensor randomisation).
    pub jpeg_quality: u8,
    /// Pile density this image was drawn with (0 isolated … 1 overlapped).
    pub density: f32,
    /// Number of carcasses placed (including dropped, fully hidden or out-of-view ones).
    pub placed: usize,
    pub timings: Timings,
}

impl RenderedSample {
    /// Visible masks of the kept instances, in `instances` order (data-layer masks).
    pub fn masks(&self) -> Vec<crate::annotations::mask::Mask> {
        let (w, h) = self.image.dimensions();
        self.instances
            .iter()
            .map(|i| export::visible_mask(&self.ids, w, h, i.id))
            .collect()
    }
}

/// The per-image RNG: ChaCha8 keyed by (preset seed space, dataset seed, image index),
/// so a sample never depends on which thread rendered it or in what order.
pub fn image_rng(opts: &RenderOptions, seed: u64, index: u64) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    let words = [
        mix64(opts.domain()),
        mix64(seed ^ 0xC41C_4E17),
        mix64(index.wrapping_add(0x5EED)),
        mix64(opts.domain() ^ seed.rotate_left(17) ^ index.rotate_left(41)),
    ];
    for (i, w) in words.iter().enumerate() {
        key[i * 8..i * 8 + 8].copy_from_slice(&w.to_le_bytes());
    }
    ChaCha8Rng::from_seed(key)
}

/// An independent RNG stream of one image for one randomisation group (carcass variety,
/// scene, distractors, lighting, camera, physics, …), keyed by (preset seed space,
/// dataset seed, image index, group). Groups draw from their own streams rather than the
/// image's main stream, so switching one group off (or adding draws to it) leaves every
/// other group's choices, and the main stream, exactly as they were.
pub fn group_rng(opts: &RenderOptions, seed: u64, index: u64, group: &str) -> ChaCha8Rng {
    let g = group.bytes().fold(0xCBF2_9CE4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01B3)
    });
    let mut key = [0u8; 32];
    let words = [
        mix64(opts.domain() ^ g),
        mix64(seed ^ 0x6A09_E667 ^ g.rotate_left(7)),
        mix64(index.wrapping_add(0xB5EE) ^ g.rotate_left(29)),
        mix64(g ^ seed.rotate_left(13) ^ index.rotate_left(37)),
    ];
    for (i, w) in words.iter().enumerate() {
        key[i * 8..i * 8 + 8].copy_from_slice(&w.to_le_bytes());
    }
    ChaCha8Rng::from_seed(key)
}

/// Renders sample `index` of dataset seed `seed`. Deterministic: same options, seed and
/// index give the same pixels, ids and labels on any machine thread count.
pub fn render_sample(
    opts: &RenderOptions,
    seed: u64,
    index: u64,
) -> anyhow::Result<RenderedSample> {
    Ok(render_traced(opts, seed, index)?.0)
}

/// [`render_sample`], also returning the id buffer as traced (distractors still carry
/// their own ids, after the lens warp) so tests can check where distractors were.
fn render_traced(
    opts: &RenderOptions,
    seed: u64,
    index: u64,
) -> anyhow::Result<(RenderedSample, Vec<u16>)> {
    opts.validate()?;
    if let Some(sample) = clutter_sample(opts, seed, index) {
        let ids = sample.ids.clone();
        return Ok((sample, ids));
    }
    let asset = asset::asset(opts.carcass.as_ref())?;
    let t0 = Instant::now();
    let mut rng = image_rng(opts, seed, index);
    let streams = scene::Streams { seed, index };
    let sc = scene::sample(&mut rng, &streams, opts, &asset);
    let t_scene = t0.elapsed();
    let tracer = trace::Tracer::build(&sc.geometry);
    let t1 = Instant::now();
    let mut frame = tracer.render(&sc.geometry, &sc.look);
    let t_trace = t1.elapsed();
    let t2 = Instant::now();
    let n = sc.resting.len();
    let mut amodal = labels::amodal_masks(&sc.geometry, &sc.look.camera, n);
    if let Some(lens) = &sc.lens {
        let (w, h) = (opts.width as usize, opts.height as usize);
        let f = &mut frame;
        lens.warp(&mut f.radiance, &mut f.depth, &mut f.ids, &mut amodal, w, h);
    }
    // Distractors are never labelled: their pixels are background in the id buffer.
    let traced_ids = frame.ids.clone();
    for id in frame.ids.iter_mut() {
        if prop_material::is_prop_id(*id) {
            *id = 0;
        }
    }
    let names: Vec<&str> = sc.resting.iter().map(|m| m.name()).collect();
    let instances = labels::instance_labels(
        &frame.ids,
        &mut amodal,
        opts.width as usize,
        opts.height as usize,
        &names,
        &opts.labels,
    );
    let t_labels = t2.elapsed();
    let t3 = Instant::now();
    frame.darken_crevices(0.45);
    let image = sc.sensor.develop(&frame.radiance, opts.width, opts.height);
    let t_sensor = t3.elapsed();
    let sample = RenderedSample {
        image,
        ids: frame.ids,
        instances,
        jpeg_quality: sc.jpeg_quality,
        density: sc.density,
        placed: n,
        timings: Timings {
            scene: t_scene,
            physics: sc.physics_time,
            build: tracer.build_time,
            trace: t_trace,
            labels: t_labels,
            sensor: t_sensor,
            encode: Duration::ZERO,
        },
    };
    Ok((sample, traced_ids))
}

/// The negatives knob's clutter coin, from its own stream: on heads the image is a
/// dead-leaves picture ([`clutter::dead_leaves`]) with no instance, and no scene is
/// sampled (its drawing time is the sample's `scene` time); a share of 0 never picks one.
fn clutter_sample(opts: &RenderOptions, seed: u64, index: u64) -> Option<RenderedSample> {
    if opts.negatives.clutter <= 0.0 {
        return None;
    }
    let t0 = Instant::now();
    let mut rng = group_rng(opts, seed, index, "clutter");
    if !rng.random_bool(opts.negatives.clutter as f64) {
        return None;
    }
    let image = clutter::dead_leaves(&mut rng, opts.width, opts.height);
    let jpeg_quality = rng.random_range(opts.jpeg_quality_range());
    Some(RenderedSample {
        image,
        ids: vec![0; opts.width as usize * opts.height as usize],
        instances: Vec::new(),
        jpeg_quality,
        density: 0.0,
        placed: 0,
        timings: Timings {
            scene: t0.elapsed(),
            ..Timings::default()
        },
    })
}

/// Encodes a sample's image in the dataset format; returns (bytes, file extension).
pub fn encode_sample(
    opts: &RenderOptions,
    s: &RenderedSample,
) -> anyhow::Result<(Vec<u8>, &'static str)> {
    Ok(match opts.format {
        ImageFormat::Jpg => (sensor::encode_jpeg(&s.image, s.jpeg_quality)?, "jpg"),
        ImageFormat::Png => (encode_png(&s.image)?, "png"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotations::coco::Segmentation;
    use crate::annotations::polygon::rle_from_polygons;
    use crate::annotations::rle::Rle;

    fn small(size: u32) -> RenderOptions {
        let mut o = RenderOptions::synthetic(size);
        o.carcasses = [3, 6];
        o
    }

    #[test]
    fn masks_are_the_id_buffer_and_polygons_agree_with_rle() {
        let o = small(128);
        let mut checked = 0;
        for i in 0..4 {
            let s = render_sample(&o, 7, i).unwrap();
            let anns = export::annotations(&s.ids, 128, 128, &s.instances, 1, 1);
            for (k, (inst, ann)) in s.instances.iter().zip(&anns).enumerate() {
                let Segmentation::Rle { counts, .. } = &ann.segmentation else {
                    panic!()
                };
                let m = Rle::from_compressed(counts, 128, 128).unwrap().decode();
                for (p, &id) in s.ids.iter().enumerate() {
                    assert_eq!(
                        m.data[p] != 0,
                        id == inst.id,
                        "pixel {p} of instance {}",
                        inst.id
                    );
                }
                assert_eq!(ann.area as u64, inst.visible_px);
                assert_eq!(s.masks()[k], m);
                assert!(inst.visible_px <= inst.amodal_px);
                let polys: Vec<Vec<f64>> =
                    serde_json::from_value(ann.extra["polygons"].clone()).unwrap();
                let back = rle_from_polygons(&polys, 128, 128).decode();
                let iou = back.iou(&m);
                // Tiny sliver instances (ignored anyway) can lose more to polygon rounding.
                if inst.visible_px >= 100 {
                    assert!(iou >= 0.98, "polygon IoU {iou} for {} px", inst.visible_px);
                    checked += 1;
                }
            }
        }
        assert!(checked >= 4, "only {checked} instances checked");
    }

    #[test]
    fn dense_piles_overlap_and_isolated_ones_do_not() {
        // Overlap = some instance has visib_fract < 0.9 (a tenth of it hidden). At the
        // dense end (density >= 0.9: pile radius about half the carcasses' footprint, 2-3
        // candidate spots per drop) stacking is forced, so nearly every image of 6+
        // carcasses must show it; 8 of 10 leaves room for a pile near the border.
        let mut dense = RenderOptions::synthetic(64);
        dense.carcasses = [6, 12];
        dense.density = [0.9, 1.0];
        let overlapped = (0..10)
            .filter(|&i| {
                let s = render_sample(&dense, 1, i).unwrap();
                s.instances.iter().any(|x| x.visib_fract < 0.9)
            })
            .count();
        assert!(overlapped >= 8, "only {overlapped}/10 dense images overlap");
        // Isolated, two carcasses: the drop picks free spots, so overlap is rare.
        let mut iso = RenderOptions::synthetic(64);
        iso.carcasses = [2, 2];
        iso.density = [0.0, 0.0];
        let overlapped = (0..10)
            .filter(|&i| {
                render_sample(&iso, 1, i)
                    .unwrap()
                    .instances
                    .iter()
                    .any(|x| x.visib_fract < 0.9)
            })
            .count();
        assert!(overlapped <= 2, "{overlapped}/10 isolated images overlap");
    }

    #[test]
    fn carcass_group_is_deterministic_and_labels_every_piece() {
        let mut o = small(96);
        o.carcasses = [5, 8];
        o.randomize.carcass = true;
        let mut differs = 0;
        for i in 0..3 {
            let a = render_sample(&o, 9, i).unwrap();
            // Second render on a one-thread pool: same pixels, ids and labels.
            let b = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| render_sample(&o, 9, i))
                .unwrap();
            assert!(
                a.image == b.image && a.ids == b.ids,
                "image {i} not reproducible"
            );
            assert_eq!(
                serde_json::to_string(&a.instances).unwrap(),
                serde_json::to_string(&b.instances).unwrap()
            );
            // Every visible pixel belongs to a placed carcass, and each kept instance's
            // mask is exactly its ids (caps and cut pieces carry their carcass's id).
            assert!(a.ids.iter().all(|&id| (id as usize) <= a.placed));
            for inst in &a.instances {
                let px = a.ids.iter().filter(|&&id| id == inst.id).count() as u64;
                assert_eq!(px, inst.visible_px);
                assert!(px > 0 && inst.visible_px <= inst.amodal_px);
            }
            let mut off = o.clone();
            off.randomize.carcass = false;
            if render_sample(&off, 9, i).unwrap().image != a.image {
                differs += 1;
            }
        }
        assert_eq!(
            differs, 3,
            "the carcass group changed only {differs}/3 images"
        );
    }

    #[test]
    fn raster_primary_matches_traced_primary() {
        let mut o = small(96);
        let s1 = render_sample(&o, 3, 0).unwrap();
        o.raster_primary = false;
        let s2 = render_sample(&o, 3, 0).unwrap();
        let same = s1.ids.iter().zip(&s2.ids).filter(|(a, b)| a == b).count();
        assert!(
            same as f64 >= 0.995 * s1.ids.len() as f64,
            "{same} of {} ids agree",
            s1.ids.len()
        );
    }

    #[test]
    fn bad_carcass_path_is_an_error_not_a_panic() {
        let mut o = small(64);
        o.carcass = Some("/nonexistent/carcass.glb".into());
        let e = render_sample(&o, 0, 0).unwrap_err();
        assert!(format!("{e:#}").contains("/nonexistent/carcass.glb"));
        let mut o = small(64);
        o.width = 0;
        assert!(render_sample(&o, 0, 0).is_err());
    }
}

#[cfg(test)]
mod randomize_tests {
    use super::*;
    use crate::annotations::coco::Segmentation;
    use crate::annotations::rle::Rle;

    fn groups(spec: &str, size: u32) -> RenderOptions {
        let mut o = RenderOptions::synthetic(size);
        o.carcasses = [3, 6];
        // `spec`: "none" or a comma list of groups.
        for g in spec.split(',').filter(|g| *g != "none") {
            o.randomize = o.randomize.with(g, true).unwrap();
        }
        o
    }

    #[test]
    fn groups_are_deterministic_and_draw_from_their_own_streams() {
        let o = groups("scene,distractors,lighting,camera", 64);
        // Same pixels, ids and labels on a one-thread pool (scheduling must not matter).
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        for i in 0..3 {
            let a = render_sample(&o, 5, i).unwrap();
            let b = one.install(|| render_sample(&o, 5, i)).unwrap();
            assert!(a.image == b.image && a.ids == b.ids && a.instances == b.instances);
        }
        // Lighting changes shading only: with it off, the same geometry, camera, lens and
        // labels (its stream is apart), but other pixels.
        let no_light = groups("scene,distractors,camera", 64);
        let mut differ = 0;
        for i in 0..3 {
            let (a, b) = (
                render_sample(&o, 5, i).unwrap(),
                render_sample(&no_light, 5, i).unwrap(),
            );
            assert_eq!(a.ids, b.ids, "image {i}");
            assert_eq!(a.instances, b.instances);
            differ += (a.image != b.image) as u32;
        }
        assert_eq!(differ, 3);
        // And each group really changes the image against the base look.
        let base = render_sample(&groups("none", 64), 5, 0).unwrap();
        for g in ["scene", "distractors", "lighting", "camera"] {
            let mut changed = 0;
            let mut on = groups(g, 64);
            // At least two objects per image (the default range starts at none).
            on.ranges.distractors = [2, 4];
            for i in 0..3 {
                let a = render_sample(&on, 5, i).unwrap();
                let b = render_sample(&groups("none", 64), 5, i).unwrap();
                changed += (a.image != b.image) as u32;
            }
            assert!(changed >= 2, "group {g} changed {changed}/3 images");
        }
        assert!(!base.instances.is_empty());
    }

    #[test]
    fn distractor_pixels_are_never_inside_a_carcass_mask() {
        let mut o = groups("distractors", 96);
        o.carcasses = [5, 8];
        o.density = [0.6, 1.0];
        o.ranges.distractors = [6, 8];
        let (mut prop_px, mut occluded) = (0usize, 0usize);
        for i in 0..4 {
            let (s, traced) = render_traced(&o, 2, i).unwrap();
            prop_px += traced
                .iter()
                .filter(|&&v| prop_material::is_prop_id(v))
                .count();
            let anns = export::annotations(&s.ids, 96, 96, &s.instances, 1, 1);
            for (inst, ann) in s.instances.iter().zip(&anns) {
                let Segmentation::Rle { counts, .. } = &ann.segmentation else {
                    panic!()
                };
                let m = Rle::from_compressed(counts, 96, 96).unwrap().decode();
                for (p, &t) in traced.iter().enumerate() {
                    assert!(
                        !(prop_material::is_prop_id(t) && m.data[p] != 0),
                        "distractor pixel {p} inside the mask of instance {}",
                        inst.id
                    );
                }
                occluded += (inst.visible_px < inst.amodal_px) as usize;
            }
        }
        assert!(prop_px > 50, "only {prop_px} distractor pixels in 4 images");
        assert!(occluded > 0);
    }

    #[test]
    fn several_lights_render_finite_values() {
        let mut o = groups("lighting", 64);
        o.ranges.lights = [4, 4];
        let asset = asset::asset(None).unwrap();
        for i in 0..3 {
            let mut rng = image_rng(&o, 3, i);
            let sc = scene::sample(&mut rng, &scene::Streams { seed: 3, index: i }, &o, &asset);
            assert_eq!(sc.look.fill.len(), 3);
            let tracer = trace::Tracer::build(&sc.geometry);
            let f = tracer.render(&sc.geometry, &sc.look);
            assert!(f
                .radiance
                .iter()
                .all(|c| c.is_finite() && c.min_element() >= 0.0));
            assert!(f.radiance.iter().map(|c| c.x + c.y + c.z).sum::<f32>() > 0.0);
        }
    }

    #[test]
    fn lens_distortion_keeps_masks_on_the_id_buffer() {
        let mut o = groups("camera", 96);
        o.ranges.lens_k1 = [-0.25, -0.25];
        o.ranges.lens_k2 = [0.0, 0.0];
        let s = render_sample(&o, 4, 0).unwrap();
        o.ranges.lens_k1 = [0.0, 0.0];
        let flat = render_sample(&o, 4, 0).unwrap();
        assert_ne!(s.ids, flat.ids, "the lens moved nothing");
        for (inst, m) in s.instances.iter().zip(s.masks()) {
            let n = m.data.iter().filter(|&&v| v != 0).count() as u64;
            assert_eq!(n, inst.visible_px);
            assert!(inst.visible_px <= inst.amodal_px);
        }
    }
}

#[cfg(test)]
mod asset_tests {
    use super::*;

    #[test]
    fn a_user_rigid_glb_renders_and_non_square_images_work() {
        // A rigid 20 x 12 x 8 cm box mesh, as a user's scan would arrive (no skin).
        let c = [-1.0f32, 1.0];
        let mut positions = Vec::new();
        for x in c {
            for y in c {
                for z in c {
                    positions.push(glam::Vec3::new(x * 0.1, y * 0.06, z * 0.04));
                }
            }
        }
        let indices = vec![
            0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1, 2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6,
            4, 1, 5, 7, 1, 7, 3,
        ];
        let normals = mesh::Mesh::compute_normals(&positions, &indices);
        let m = mesh::Mesh {
            positions,
            normals,
            indices,
            skin: None,
        };
        let path = std::env::temp_dir().join(format!("ct-box-{}.glb", std::process::id()));
        std::fs::write(&path, glb::to_glb(&m).unwrap()).unwrap();
        let mut o = RenderOptions::synthetic(64);
        o.height = 48;
        o.carcasses = [2, 3];
        o.carcass = Some(path.clone());
        let s = render_sample(&o, 0, 0).unwrap();
        assert_eq!(s.image.dimensions(), (64, 48));
        assert_eq!(s.ids.len(), 64 * 48);
        assert!(!s.instances.is_empty());
        // The carcass group keeps a user's mesh (families are the generator's): sizes,
        // skin marks and tears apply, cuts need the generator's skin and are skipped.
        o.randomize.carcass = true;
        let s = render_sample(&o, 0, 0).unwrap();
        assert!(!s.instances.is_empty());
        let _ = std::fs::remove_file(path);
    }
}
