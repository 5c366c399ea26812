//! Sampling one image's scene from its RNG: how many carcasses and how densely piled,
//! their poses, resting modes and skins, the drop into a pile, the camera, light, room
//! and plate, and the sensor. Every choice is drawn from the per-image ChaCha stream in a
//! fixed order, so (dataset seed, image index) fixes the scene exactly.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use glam::{Vec2, Vec3};
use rand::Rng;
use rayon::prelude::*;

use super::camera::Camera;
use super::carcass;
use super::light::{kelvin_to_rgb, AreaLight, Environment};
use super::material::{Background, SkinMaterial};
use super::mesh::Mesh;
use super::pile::{self, HeightField, RestingMode};
use super::preset::RenderOptions;
use super::sensor::Sensor;
use super::skin::{pose_mesh, Pose};
use super::trace::{Geometry, Look};

/// A carcass mesh ready to instance: the mesh and its per-vertex redness.
pub struct Asset {
    pub mesh: Mesh,
    pub redness: Vec<f32>,
}

impl Asset {
    pub fn new(mesh: Mesh) -> Asset {
        // Redness spots are defined on the generator's anatomy; meshes that carry the
        // generator's joint names get them, other meshes get plain skin.
        let ours = mesh.skin.as_ref().is_some_and(|s| {
            carcass::JOINT_NAMES
                .iter()
                .all(|n| s.joints.iter().any(|j| j.name == *n))
        });
        let spots = if ours {
            carcass::red_spots()
        } else {
            Vec::new()
        };
        let redness = mesh
            .positions
            .iter()
            .map(|&p| {
                spots
                    .iter()
                    .map(|(c, r)| (-(p - *c).length_squared() / (r * r)).exp())
                    .fold(0.0f32, f32::max)
            })
            .collect();
        Asset { mesh, redness }
    }
}

/// Loads (once per process) the carcass asset named by the options.
pub fn asset(path: Option<&PathBuf>) -> anyhow::Result<Arc<Asset>> {
    static CACHE: OnceLock<Mutex<HashMap<Option<PathBuf>, Arc<Asset>>>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = path.cloned();
    if let Some(a) = cache
        .lock()
        .map_err(|_| anyhow::anyhow!("asset cache poisoned"))?
        .get(&key)
    {
        return Ok(a.clone());
    }
    let mesh = match path {
        None => super::glb::default_carcass()?,
        Some(p) => super::glb::load(p)?,
    };
    let a = Arc::new(Asset::new(mesh));
    cache
        .lock()
        .map_err(|_| anyhow::anyhow!("asset cache poisoned"))?
        .insert(key, a.clone());
    Ok(a)
}

/// One sampled scene: geometry, appearance, sensor, and per-instance facts.
pub struct Scene {
    pub geometry: Geometry,
    pub look: Look,
    pub sensor: Sensor,
    pub resting: Vec<RestingMode>,
    pub density: f32,
    pub jpeg_quality: u8,
}

fn uni<R: Rng>(rng: &mut R, r: [f32; 2]) -> f32 {
    if r[1] > r[0] {
        rng.random_range(r[0]..r[1])
    } else {
        r[0]
    }
}

/// Samples a scene. `rng` is the image's own stream.
pub fn sample<R: Rng>(rng: &mut R, opts: &RenderOptions, asset: &Asset) -> Scene {
    let n = rng.random_range(opts.carcasses[0]..=opts.carcasses[1].max(opts.carcasses[0])) as usize;
    let density = uni(rng, opts.density);

    // Camera: top view, jittered height, tilt, roll and field of view.
    let cam_h = uni(rng, opts.camera_height);
    let fov = uni(rng, opts.fov_deg).to_radians();
    let half_view =
        cam_h * (fov * 0.5).tan() * opts.width.max(opts.height) as f32 / opts.height as f32;
    let tilt = rng.random_range(0.0..=opts.tilt_max_deg.to_radians());
    let tilt_dir = rng.random_range(0.0..std::f32::consts::TAU);
    let roll = rng.random_range(0.0..std::f32::consts::TAU);
    let eye = Vec3::new(0.0, 0.0, cam_h);
    let camera = Camera::top_view(eye, tilt, tilt_dir, roll, fov, opts.width, opts.height);
    // Where the camera actually looks on the plate (tilt moves it).
    let look_at = camera
        .plate_point(opts.width as f32 * 0.5, opts.height as f32 * 0.5)
        .map_or(Vec2::ZERO, |p| p.truncate());

    // Pile: centre near the view centre (off-centre piles get cut by the border), spread
    // set by the density: isolated ~2.2x the carcasses' footprint, overlapped ~0.5x.
    let centre = look_at
        + Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
            * half_view
            * opts.pile_offset;
    let footprint = 0.055 * n as f32;
    let spread = 2.4 + (0.45 - 2.4) * density;
    let radius = ((footprint * spread / std::f32::consts::PI).sqrt()).min(half_view * 1.1);
    let k = (12.0 + (2.0 - 12.0) * density).round().max(1.0) as usize;
    // The map only needs to cover where carcasses can land: the candidate disc plus a
    // carcass length (keeps it small for wide views).
    let mut hf = HeightField::around(centre, radius + 0.45, 0.004);

    let mut geo = Geometry::default();
    let mut skins = Vec::with_capacity(n);
    let mut resting = Vec::with_capacity(n);
    let wsum: f32 = opts.resting_weights.iter().sum::<f32>().max(1e-6);
    // Draw every random choice first (fixed order), then skin in parallel: skinning is
    // pure, so the scene does not depend on scheduling; drops stay sequential.
    let mut plans = Vec::with_capacity(n);
    for _ in 0..n {
        let pose = Pose::sample(rng, &opts.pose);
        let u = rng.random_range(0.0..wsum);
        let mode = if u < opts.resting_weights[0] {
            RestingMode::BreastUp
        } else if u < opts.resting_weights[0] + opts.resting_weights[1] {
            RestingMode::BreastDown
        } else {
            RestingMode::Side
        };
        let yaw = rng.random_range(0.0..std::f32::consts::TAU);
        let q = pile::resting_rotation(rng, mode, yaw);
        let cands = pile::candidates(rng, centre, radius, k);
        skins.push(SkinMaterial::sample(rng, opts.skin_yellow));
        plans.push((pose, mode, q, cands));
    }
    let posed: Vec<(Vec<Vec3>, Vec<Vec3>)> = plans
        .par_iter()
        .map(|(pose, _, q, _)| {
            let (pos, nor) = pose_mesh(&asset.mesh, pose);
            pile::orient(&pos, &nor, *q)
        })
        .collect();
    for (inst, ((local, mut nor), (_, mode, _, cands))) in posed.into_iter().zip(plans).enumerate()
    {
        let placed = pile::drop_one(&mut hf, &local, &mut nor, &cands);
        let base = geo.positions.len() as u32;
        geo.positions.extend(placed);
        geo.normals.extend(nor);
        geo.rest.extend_from_slice(&asset.mesh.positions);
        geo.redness.extend_from_slice(&asset.redness);
        for t in asset.mesh.indices.chunks_exact(3) {
            geo.triangles.push([t[0] + base, t[1] + base, t[2] + base]);
            geo.tri_instance.push(inst as u16);
        }
        resting.push(mode);
    }

    // Key light: a soft box above, off to one side; its colour temperature; the room.
    let lh = uni(rng, opts.light_height);
    let size = uni(rng, opts.light_size);
    let a = rng.random_range(0.0..std::f32::consts::TAU);
    let off = Vec2::new(a.cos(), a.sin()) * uni(rng, opts.light_offset);
    let lc = look_at + off;
    let la = rng.random_range(0.0..std::f32::consts::TAU);
    let aspect = rng.random_range(0.5..1.0);
    let u = Vec3::new(la.cos(), la.sin(), 0.0) * size * 0.5;
    let v = Vec3::new(-la.sin(), la.cos(), 0.0) * size * 0.5 * aspect;
    let kelvin = uni(rng, opts.light_kelvin);
    let light_rgb = kelvin_to_rgb(kelvin);
    let area = 4.0 * u.length() * v.length();
    let color = light_rgb / area;
    let key_centre = Vec3::new(lc.x, lc.y, lh);
    let irradiance = 1.0 / (lh * lh);
    let amb_ratio = uni(rng, opts.ambient);
    let room_rgb = kelvin_to_rgb(kelvin + rng.random_range(-800.0..800.0));
    let env = Environment {
        ambient: room_rgb * irradiance * amb_ratio / std::f32::consts::PI,
        key_dir: key_centre.normalize_or(Vec3::Z),
        glow: light_rgb * irradiance * rng.random_range(0.05..0.25),
        seed: rng.random(),
        structure: rng.random_range(0.2..0.8),
    };
    let light = AreaLight {
        centre: key_centre,
        u,
        v,
        color,
    };
    let background = Background::sample(
        rng,
        opts.p_belt,
        opts.p_stains,
        opts.steel_roughness,
        half_view * 1.5,
    );

    let wbj = opts.white_balance_jitter;
    // The camera's white balance corrects most of the light's colour (auto WB or a preset
    // close to the lamp), never all of it, and adds its own small error.
    let correction = uni(rng, opts.white_balance_correction);
    let wb_fix = Vec3::ONE / light_rgb.max(Vec3::splat(1e-3)) * light_rgb.y;
    let wb_fix = Vec3::ONE.lerp(wb_fix, correction);
    let sensor = Sensor {
        exposure_ev: uni(rng, opts.exposure_ev),
        target: 0.2,
        wb: wb_fix
            * Vec3::new(
                1.0 + rng.random_range(-wbj..=wbj),
                1.0,
                1.0 + rng.random_range(-wbj..=wbj),
            ),
        vignette: uni(rng, opts.vignette),
        blur: uni(rng, opts.blur_px),
        shot: uni(rng, opts.shot_noise),
        read: uni(rng, opts.shot_noise) * 0.2,
        seed: rng.random(),
    };
    let q = opts.jpeg_quality;
    let jpeg_quality = rng.random_range(q[0].min(q[1])..=q[1].max(q[0]));
    let look = Look {
        camera,
        light,
        env,
        background,
        skins,
        shadow_samples: opts.shadow_samples,
        shadow_filter: opts.shadow_filter_px as usize,
        raster_primary: opts.raster_primary,
        reflections: opts.reflections,
        seed: rng.random(),
    };
    Scene {
        geometry: geo,
        look,
        sensor,
        resting,
        density,
        jpeg_quality,
    }
}
