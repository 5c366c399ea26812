//! Sampling one image's scene from its RNG: how many carcasses and how densely piled,
//! their poses, resting modes and skins, the drop into a pile, the camera, light, room
//! and plate, and the sensor. Every choice is drawn from the per-image ChaCha stream in a
//! fixed order, so (dataset seed, image index) fixes the scene exactly.

use std::borrow::Cow;

use glam::{Quat, Vec2, Vec3};
use rand::Rng;
use rayon::prelude::*;

use super::asset::Asset;
use super::camera::Camera;
use super::distractor;
use super::lens::Lens;
use super::light::{kelvin_to_rgb, AreaLight, Environment};
use super::line_surface::LineSurface;
use super::material::{Background, SkinMaterial};
use super::pile::{self, HeightField, RestingMode};
use super::preset::RenderOptions;
use super::sensor::Sensor;
use super::settle;
use super::skin::{pose_mesh, Pose};
use super::trace::{Geometry, Look};
use super::variety::Variety;

/// One sampled scene: geometry, appearance, sensor, and per-instance facts.
pub struct Scene {
    pub geometry: Geometry,
    pub look: Look,
    pub sensor: Sensor,
    pub resting: Vec<RestingMode>,
    pub density: f32,
    pub jpeg_quality: u8,
    /// Time spent posing and settling the pile with physics (zero for the height-field drop).
    pub physics_time: std::time::Duration,
    /// Radial distortion applied to the traced frame (the `camera` group); None = pinhole.
    pub lens: Option<Lens>,
}

fn uni<R: Rng>(rng: &mut R, r: [f32; 2]) -> f32 {
    if r[1] > r[0] {
        rng.random_range(r[0]..r[1])
    } else {
        r[0]
    }
}

/// Where an image's per-group RNG streams come from ([`super::group_rng`]): what a
/// randomisation group draws goes to its own stream, not the main `rng`.
#[derive(Clone, Copy, Debug)]
pub struct Streams {
    pub seed: u64,
    pub index: u64,
}

impl Streams {
    /// The stream of `group` (e.g. "carcass", "scene", "distractors", "lighting",
    /// "camera", "physics") for this image.
    pub fn rng(&self, opts: &RenderOptions, group: &str) -> rand_chacha::ChaCha8Rng {
        super::group_rng(opts, self.seed, self.index, group)
    }
}

/// Samples a scene. `rng` is the image's own stream; the helpers below draw from it in
/// this order: count and density, camera, pile layout, each carcass's plan, light and
/// room, plate, sensor, JPEG quality, render seed. Changing that order changes every image.
///
/// The randomisation groups (`opts.randomize`) draw from their own streams and replace
/// or add to those choices after the main stream's draws, which all still happen: a group
/// switched on or off never shifts the main stream or another group.
pub fn sample<R: Rng>(
    rng: &mut R,
    streams: &Streams,
    opts: &RenderOptions,
    asset: &Asset,
) -> Scene {
    let groups = opts.randomize;
    let mut scene_rng = streams.rng(opts, "scene");
    let mut cam_rng = streams.rng(opts, "camera");
    let mut light_rng = streams.rng(opts, "lighting");
    let n = rng.random_range(opts.carcasses[0]..=opts.carcasses[1].max(opts.carcasses[0])) as usize;
    let density = uni(rng, opts.density);
    let mut view = View::sample(rng, opts);
    if groups.camera {
        view = View::sample(&mut cam_rng, &wide_camera(opts));
    }
    // The negatives knob: two coin flips from its own stream (a share of 0 never
    // changes an image).
    let mut neg_rng = streams.rng(opts, "negatives");
    let neg_empty = neg_rng.random_bool(opts.negatives.empty as f64);
    let neg_props = neg_rng.random_bool(opts.negatives.distractors as f64);
    let empty = (groups.scene && scene_rng.random_bool(opts.ranges.p_empty as f64)) || neg_empty;
    let mut layout = PileLayout::sample(rng, opts, &view, n, density);
    if groups.scene {
        cut_by_frame(&mut scene_rng, opts, &mut layout, &view);
    }
    let (mut plans, mut skins) = plan_carcasses(rng, opts, &layout, n);
    if empty {
        // A pure negative: the carcasses were planned (the main stream stays aligned)
        // but none is placed.
        plans.clear();
        skins.clear();
    }
    if groups.carcass {
        vary_carcasses(streams, opts, asset, &mut plans, &mut skins);
    }
    // The physics group settles the pile with rigid-body contact; its draws come from its
    // own stream, so the main stream (and every choice after this) is unchanged.
    let physics = groups
        .physics
        .then(|| (streams.rng(opts, "physics"), opts.resting_weights));
    let (mut geo, resting, physics_time) = build_pile(asset, &layout, plans, physics);
    let props = if groups.distractors || neg_props {
        // The knob's images get at least one object; the group keeps its own range.
        let at_least = u32::from(!groups.distractors);
        add_distractors(streams, opts, at_least, &mut geo, &layout, &view)
    } else {
        Vec::new()
    };
    let mut lighting = Lighting::sample(rng, opts, view.look_at);
    let mut fill = Vec::new();
    if groups.lighting {
        let wide = wide_lighting(&mut light_rng, opts);
        lighting = Lighting::sample(&mut light_rng, &wide, view.look_at);
        fill = fill_lights(&mut light_rng, opts, view.look_at, &lighting.light);
    }
    let background = floor(rng, &mut scene_rng, groups.scene, opts, &view);
    let mut sensor = sample_sensor(rng, opts, lighting.light_rgb);
    let mut jpeg_quality = rng.random_range(opts.jpeg_quality_range());
    if groups.lighting {
        widen_exposure(&mut light_rng, opts, &mut sensor, lighting.light_rgb);
    }
    // Dark belts, crates and wet films (scene) and the wide exposure range (lighting)
    // would blow pale carcasses out under median auto-exposure: protect highlights.
    sensor.highlight_guard = groups.scene || groups.lighting;
    let mut lens = None;
    if groups.camera {
        let (l, q) = widen_sensor(&mut cam_rng, opts, &mut sensor);
        lens = Some(l);
        jpeg_quality = q;
    }
    let look = Look {
        camera: view.camera,
        light: lighting.light,
        fill,
        env: lighting.env,
        background,
        skins,
        props,
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
        physics_time,
        lens,
    }
}

/// The options with the `camera` group's height, field of view and tilt ranges.
fn wide_camera(opts: &RenderOptions) -> RenderOptions {
    RenderOptions {
        camera_height: opts.ranges.camera_height,
        fov_deg: opts.ranges.fov_deg,
        tilt_max_deg: opts.ranges.tilt_max_deg,
        ..opts.clone()
    }
}

/// The options with the `lighting` group's key-light ranges: from near, small and hard
/// (sharp shadows) to large and far, any colour temperature of the range, dim to bright
/// rooms; with probability `ranges.p_glare` the key hangs over the view, so steel and
/// wet surfaces mirror it (specular glare).
fn wide_lighting<R: Rng>(rng: &mut R, opts: &RenderOptions) -> RenderOptions {
    let glare = rng.random_bool(opts.ranges.p_glare as f64);
    RenderOptions {
        light_height: [0.6, 2.6],
        light_size: [0.03, 1.5],
        light_offset: if glare { [0.0, 0.6] } else { [0.8, 2.5] },
        light_kelvin: opts.ranges.light_kelvin,
        ambient: [0.05, 0.8],
        ..opts.clone()
    }
}

/// The `scene` group's framing: with probability `ranges.p_cut` the pile is pushed
/// towards the border and spread wider, so carcasses are cut by the frame.
fn cut_by_frame<R: Rng>(rng: &mut R, opts: &RenderOptions, layout: &mut PileLayout, view: &View) {
    if !rng.random_bool(opts.ranges.p_cut as f64) {
        return;
    }
    let a = rng.random_range(0.0..std::f32::consts::TAU);
    let d = rng.random_range(0.5..1.05) * view.half_view;
    layout.centre = view.look_at + Vec2::new(a.cos(), a.sin()) * d;
    layout.radius = (layout.radius * rng.random_range(1.0..1.6)).min(view.half_view * 1.4);
}

/// The `distractors` group (and the negatives knob's distractor images):
/// `ranges.distractors` objects on and around the pile, raised to at least `at_least`.
fn add_distractors(
    streams: &Streams,
    opts: &RenderOptions,
    at_least: u32,
    geo: &mut Geometry,
    layout: &PileLayout,
    view: &View,
) -> Vec<super::prop_material::PropMaterial> {
    let mut rng = streams.rng(opts, "distractors");
    let r = opts.ranges.distractors;
    let (lo, hi) = (r[0].max(at_least), r[1].max(r[0]).max(at_least));
    let count = rng.random_range(lo..=hi) as usize;
    let area = distractor::Area {
        pile_centre: layout.centre,
        pile_radius: layout.radius,
        view_centre: view.look_at,
        half_view: view.half_view,
    };
    distractor::place(&mut rng, geo, &area, count)
}

/// The `lighting` group's further lights (`ranges.lights` in all, the key included):
/// soft boxes of several sizes and near point-like lamps, each with its own colour
/// temperature and a strength relative to the key light at the view centre.
fn fill_lights<R: Rng>(
    rng: &mut R,
    opts: &RenderOptions,
    look_at: Vec2,
    key: &AreaLight,
) -> Vec<AreaLight> {
    let r = opts.ranges.lights;
    let count = rng.random_range(r[0]..=r[1].max(r[0])) as usize - 1;
    let target = look_at.extend(0.0);
    // Irradiance a light of unit-luminance colour gives at the view centre, per unit of
    // its `color` (cosine at the light, inverse square).
    let reach = |l: &AreaLight| {
        let d = l.centre - target;
        let d2 = d.length_squared().max(1e-4);
        l.area() * (d.z / d2.sqrt()).max(0.05) / d2
    };
    let lum = Vec3::new(0.2126, 0.7152, 0.0722);
    let key_e = key.color.dot(lum) * reach(key);
    (0..count)
        .map(|_| {
            let point_like = rng.random_bool(0.4);
            let size = if point_like {
                rng.random_range(0.01..0.06)
            } else {
                rng.random_range(0.15..1.2)
            };
            let h = rng.random_range(0.5..2.5);
            let a = rng.random_range(0.0..std::f32::consts::TAU);
            // Soft boxes stay out of the mirror view (the key's glare is drawn apart);
            // point-like lamps may glint anywhere.
            let span = if point_like { 0.0..2.0 } else { 0.7..2.5 };
            let off = Vec2::new(a.cos(), a.sin()) * rng.random_range(span);
            let c = look_at + off;
            let la = rng.random_range(0.0..std::f32::consts::TAU);
            let aspect = rng.random_range(0.3..1.0);
            let u = Vec3::new(la.cos(), la.sin(), 0.0) * size * 0.5;
            let v = Vec3::new(-la.sin(), la.cos(), 0.0) * size * 0.5 * aspect;
            let rgb = kelvin_to_rgb(uni(rng, opts.ranges.light_kelvin));
            let strength = rng.random_range(0.1..0.9);
            let mut l = AreaLight {
                centre: Vec3::new(c.x, c.y, h),
                u,
                v,
                color: rgb,
            };
            l.color = rgb * (strength * key_e / reach(&l));
            l
        })
        .collect()
}

/// The `lighting` group's exposure and white-balance ranges (wider than the base).
fn widen_exposure<R: Rng>(rng: &mut R, opts: &RenderOptions, sensor: &mut Sensor, light_rgb: Vec3) {
    let wide = RenderOptions {
        white_balance_jitter: opts.ranges.white_balance_jitter,
        white_balance_correction: [0.5, 1.0],
        exposure_ev: opts.ranges.exposure_ev,
        ..opts.clone()
    };
    let s = sample_sensor(rng, &wide, light_rgb);
    sensor.exposure_ev = s.exposure_ev;
    sensor.wb = s.wb;
}

/// The `camera` group's optics and sensor: lens distortion, motion blur along a belt
/// direction, shot / read / colour noise, JPEG quality. Returns the lens and the quality.
fn widen_sensor<R: Rng>(rng: &mut R, opts: &RenderOptions, sensor: &mut Sensor) -> (Lens, u8) {
    let r = &opts.ranges;
    let lens = Lens {
        k1: uni(rng, r.lens_k1),
        k2: uni(rng, r.lens_k2),
    };
    sensor.motion = if rng.random_bool(r.p_motion_blur as f64) {
        let a = rng.random_range(0.0..std::f32::consts::TAU);
        let len = uni(rng, r.motion_blur_px) * opts.width as f32 / 640.0;
        [a.cos() * len, a.sin() * len]
    } else {
        [0.0; 2]
    };
    sensor.shot = uni(rng, r.shot_noise);
    sensor.read = uni(rng, r.read_noise);
    sensor.mono_noise = 1.0 - uni(rng, r.colour_noise);
    sensor.vignette = uni(rng, [0.0, 0.5]);
    sensor.blur = uni(rng, [0.2, 1.4]);
    let q = r.jpeg_quality;
    (lens, rng.random_range(q[0]..=q[1].max(q[0])))
}

/// The camera and what it sees of the plate: the pile and the light are placed relative
/// to where the camera actually looks, and the plate is sized by the half view.
struct View {
    camera: Camera,
    /// Where the image centre meets the plate (tilt moves it off the origin).
    look_at: Vec2,
    /// Half the plate width seen along the image's longer side, at the camera's height.
    half_view: f32,
}

impl View {
    /// Top view with jittered height, field of view, tilt (and its direction) and roll.
    fn sample<R: Rng>(rng: &mut R, opts: &RenderOptions) -> View {
        let cam_h = uni(rng, opts.camera_height);
        let fov = uni(rng, opts.fov_deg).to_radians();
        let half_view =
            cam_h * (fov * 0.5).tan() * opts.width.max(opts.height) as f32 / opts.height as f32;
        let tilt = rng.random_range(0.0..=opts.tilt_max_deg.to_radians());
        let tilt_dir = rng.random_range(0.0..std::f32::consts::TAU);
        let roll = rng.random_range(0.0..std::f32::consts::TAU);
        let eye = Vec3::new(0.0, 0.0, cam_h);
        let camera = Camera::top_view(eye, tilt, tilt_dir, roll, fov, opts.width, opts.height);
        let look_at = camera
            .plate_point(opts.width as f32 * 0.5, opts.height as f32 * 0.5)
            .map_or(Vec2::ZERO, |p| p.truncate());
        View {
            camera,
            look_at,
            half_view,
        }
    }
}

/// Where the pile goes and how tight it is: the disc drop positions are drawn from, and
/// how many each carcass tries (it lands where it rests lowest, so more = more isolated).
struct PileLayout {
    centre: Vec2,
    radius: f32,
    /// Drop positions tried per carcass.
    k: usize,
}

impl PileLayout {
    /// Centre near the view centre (off-centre piles get cut by the border), spread set
    /// by the density: isolated ~2.2x the carcasses' footprint, overlapped ~0.5x.
    fn sample<R: Rng>(
        rng: &mut R,
        opts: &RenderOptions,
        view: &View,
        n: usize,
        density: f32,
    ) -> PileLayout {
        let centre = view.look_at
            + Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                * view.half_view
                * opts.pile_offset;
        let footprint = 0.055 * n as f32;
        let spread = 2.4 + (0.45 - 2.4) * density;
        let radius = ((footprint * spread / std::f32::consts::PI).sqrt()).min(view.half_view * 1.1);
        let k = (12.0 + (2.0 - 12.0) * density).round().max(1.0) as usize;
        PileLayout { centre, radius, k }
    }
}

/// Every random choice for one carcass, drawn before any skinning.
struct CarcassPlan {
    pose: Pose,
    mode: RestingMode,
    rotation: Quat,
    candidates: Vec<Vec2>,
    /// Family, parts and torn skin (carcass randomisation group only).
    variety: Option<Variety>,
}

/// What the pile lies on: the main stream's plate or belt, which it always draws, replaced
/// with the scene group on by a processing-line surface from the scene stream.
fn floor<R: Rng>(
    rng: &mut R,
    scene_rng: &mut rand_chacha::ChaCha8Rng,
    scene: bool,
    opts: &RenderOptions,
    view: &View,
) -> Background {
    let background = Background::sample(
        rng,
        opts.p_belt,
        opts.p_stains,
        opts.steel_roughness,
        view.half_view * 1.5,
    );
    if !scene {
        return background;
    }
    Background::Line(Box::new(LineSurface::sample(
        scene_rng,
        &opts.ranges,
        view.look_at,
        view.half_view * 1.2,
    )))
}

/// The carcass group: each planned carcass's variety (family, size, parts, skin marks,
/// tears), drawn from the group's own stream, one sub-stream per carcass.
fn vary_carcasses(
    streams: &Streams,
    opts: &RenderOptions,
    asset: &Asset,
    plans: &mut [CarcassPlan],
    skins: &mut [SkinMaterial],
) {
    let mut stream = streams.rng(opts, "carcass");
    for (plan, skin) in plans.iter_mut().zip(skins) {
        let mut r = Variety::instance_rng(&mut stream);
        let user = opts.carcass.is_some();
        plan.variety = Some(Variety::sample(&mut r, asset, user, &mut plan.pose, skin));
    }
}

/// Draws every carcass's pose, resting mode, rotation, drop candidates and skin, in a
/// fixed order per carcass, so skinning can then run in parallel without touching `rng`.
fn plan_carcasses<R: Rng>(
    rng: &mut R,
    opts: &RenderOptions,
    layout: &PileLayout,
    n: usize,
) -> (Vec<CarcassPlan>, Vec<SkinMaterial>) {
    let wsum: f32 = opts.resting_weights.iter().sum::<f32>().max(1e-6);
    let mut skins = Vec::with_capacity(n);
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
        let rotation = pile::resting_rotation(rng, mode, yaw);
        let candidates = pile::candidates(rng, layout.centre, layout.radius, layout.k);
        skins.push(SkinMaterial::sample(rng, opts.skin_yellow));
        plans.push(CarcassPlan {
            pose,
            mode,
            rotation,
            candidates,
            variety: None,
        });
    }
    (plans, skins)
}

/// Skins and orients every carcass in parallel (pure, so the result does not depend on
/// scheduling), then drops them one by one onto the height field, in plan order. With
/// `physics` (the physics stream and the resting-mode weights) the pile is instead dropped
/// and settled by rigid-body physics (`settle.rs`); a pile it cannot simulate (a mesh
/// without volume) falls back to the height field. Returns the time spent in physics.
fn build_pile(
    asset: &Asset,
    layout: &PileLayout,
    plans: Vec<CarcassPlan>,
    physics: Option<(rand_chacha::ChaCha8Rng, [f32; 3])>,
) -> (Geometry, Vec<RestingMode>, std::time::Duration) {
    let mut geo = Geometry::default();
    let mut resting = Vec::with_capacity(plans.len());
    // Each carcass's own mesh (its family's, cut and torn) when the carcass group is on.
    let bodies: Vec<Cow<Asset>> = plans
        .par_iter()
        .map(|plan| match &plan.variety {
            Some(v) => v.build(asset),
            None => Cow::Borrowed(asset),
        })
        .collect();
    let push = |geo: &mut Geometry, inst: usize, body: &Asset, placed: Vec<Vec3>, nor| {
        let base = geo.positions.len() as u32;
        geo.positions.extend(placed);
        geo.normals.extend(nor);
        geo.rest.extend_from_slice(&body.mesh.positions);
        geo.redness.extend_from_slice(&body.redness);
        for t in body.mesh.indices.chunks_exact(3) {
            geo.triangles.push([t[0] + base, t[1] + base, t[2] + base]);
            geo.tri_instance.push(inst as u16);
        }
    };
    if let Some((mut rng, weights)) = physics {
        let t0 = std::time::Instant::now();
        let posed: Vec<(Vec<Vec3>, Vec<Vec3>)> = plans
            .par_iter()
            .zip(&bodies)
            .map(|(plan, body)| pose_mesh(&body.mesh, &plan.pose))
            .collect();
        // Hull parts follow each carcass's own mesh (families and cuts change it).
        let parts: Vec<Vec<u16>> = bodies
            .iter()
            .map(|b| settle::vertex_parts(&b.mesh))
            .collect();
        let parts: Vec<&[u16]> = parts.iter().map(|p| p.as_slice()).collect();
        let pile = settle::drop_pile(
            &mut rng,
            weights,
            layout.centre,
            layout.radius,
            &posed,
            &parts,
        );
        if let Ok(pile) = pile {
            for (inst, ((placed, nor, mode), body)) in
                pile.carcasses.into_iter().zip(&bodies).enumerate()
            {
                push(&mut geo, inst, body, placed, nor);
                resting.push(mode);
            }
            return (geo, resting, t0.elapsed());
        }
    }
    // The map only needs to cover where carcasses can land: the candidate disc plus a
    // carcass length (keeps it small for wide views).
    let mut hf = HeightField::around(layout.centre, layout.radius + 0.45, 0.004);
    let posed: Vec<(Vec<Vec3>, Vec<Vec3>)> = plans
        .par_iter()
        .zip(&bodies)
        .map(|(plan, body)| {
            let (pos, nor) = pose_mesh(&body.mesh, &plan.pose);
            pile::orient(&pos, &nor, plan.rotation)
        })
        .collect();
    for (inst, (((local, mut nor), plan), body)) in
        posed.into_iter().zip(&plans).zip(&bodies).enumerate()
    {
        let placed = pile::drop_one(&mut hf, &local, &mut nor, &plan.candidates);
        push(&mut geo, inst, body, placed, nor);
        resting.push(plan.mode);
    }
    (geo, resting, std::time::Duration::ZERO)
}

/// The key light, the room it sits in, and its colour (the sensor's white balance
/// corrects towards it).
struct Lighting {
    light: AreaLight,
    env: Environment,
    light_rgb: Vec3,
}

impl Lighting {
    /// Key light: a soft box above, off to one side of `look_at`; its colour
    /// temperature; the room's ambient, glow and structure.
    fn sample<R: Rng>(rng: &mut R, opts: &RenderOptions, look_at: Vec2) -> Lighting {
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
        Lighting {
            light,
            env,
            light_rgb,
        }
    }
}

/// The sensor: exposure, white balance (correcting most, never all, of the light's
/// colour, plus its own small error), vignette, blur and noise.
fn sample_sensor<R: Rng>(rng: &mut R, opts: &RenderOptions, light_rgb: Vec3) -> Sensor {
    let wbj = opts.white_balance_jitter;
    // The camera's white balance corrects most of the light's colour (auto WB or a preset
    // close to the lamp), never all of it, and adds its own small error.
    let correction = uni(rng, opts.white_balance_correction);
    let wb_fix = Vec3::ONE / light_rgb.max(Vec3::splat(1e-3)) * light_rgb.y;
    let wb_fix = Vec3::ONE.lerp(wb_fix, correction);
    Sensor {
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
        mono_noise: 0.0,
        motion: [0.0; 2],
        highlight_guard: false,
        seed: rng.random(),
    }
}
