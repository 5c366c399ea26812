//! Piles settled by rigid-body physics (rapier3d): the `physics` randomisation group.
//!
//! One concept: settling a pile with rigid-body physics — each carcass as convex hulls of
//! its skin parts, the rapier world with its fixed step, and the settled poses (about 490
//! lines of code and 360 of tests, which need the same fixtures).
//!
//! The height-field drop (`pile.rs`) only knows the top surface of what fell before, so a
//! carcass can never lean against another one's side or slide off a pile; here each
//! carcass, already posed and turned into its drop orientation, becomes one rigid body made
//! of a few convex hulls, one per skin part (body, thighs, drumsticks, wing segments: a
//! carcass with spread wings is far from convex, and a single hull would hold its
//! neighbours off by centimetres). The bodies are dropped together from staggered heights
//! onto the plate (a half-space at z = 0) inside a ring of guide walls, and stepped with a
//! fixed dt and fixed iteration counts until every body sleeps or a step cap is reached.
//! What comes back is each body's rigid motion; the caller moves the render mesh with it,
//! so ray tracing and labels are unchanged.
//!
//! Determinism: the inputs are fixed by the caller's draws, rapier is built with
//! `enhanced-determinism` (libm maths, no SIMD reordering), bodies are inserted in plan
//! order and the solver runs single-threaded, so the same plans give the same poses.
//! Nothing here draws random numbers except [`DropPlan::sample`], from the RNG it is given
//! (the image's "physics" stream).

use std::time::{Duration, Instant};

use glam::{Quat, Vec2, Vec3};
use rand::Rng;
use rapier3d::prelude::{
    CoefficientCombineRule, ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};

use super::mesh::Mesh;
use super::pile::{self, RestingMode};

/// Density of chicken meat (kg/m³): masses come from hull volumes.
const MEAT_DENSITY: f32 = 1050.0;
/// Wet skin on wet skin or steel: sticky, barely slides (dynamic friction ~0.7-0.9).
const FRICTION: f32 = 0.8;
/// A carcass is soft: it does not bounce.
const RESTITUTION: f32 = 0.02;
/// Energy lost in the soft tissue while it deforms, as damping of the rigid motion (keeps
/// a settling carcass from rocking and rolling like a hard shell would).
const LINEAR_DAMPING: f32 = 0.6;
const ANGULAR_DAMPING: f32 = 2.5;
/// Fixed time step (s) and solver iterations: the simulation's cost and result depend on
/// nothing else.
/// 45 Hz needs a third fewer steps than 60 Hz for the same piles; release speeds stay
/// under ~1.5 m/s, 3 cm a step, which speculative contacts catch.
const DT: f32 = 1.0 / 45.0;
const SOLVER_ITERATIONS: usize = 4;
/// Step cap (6 s of simulated time): a pile still moving then is taken as it is.
const MAX_STEPS: usize = 270;
/// Contact stiffness (natural frequency, Hz; twice that against the plate and walls).
/// Rapier's default 30 Hz let 12-carcass piles sink up to 1.4 cm into each other (at
/// 60 Hz steps); at or above the step rate a stack jitters and never sleeps.
const CONTACT_HZ: f32 = 34.0;
/// How long a body must stay still before it sleeps (s); when all sleep the pile is settled.
const TIME_UNTIL_SLEEP: f32 = 0.2;
/// Rapier's tolerances (sleep speed, slop, prediction distance) scale with this length:
/// a carcass is ~0.25 m long, not a 1 m game object.
const LENGTH_UNIT: f32 = 0.1;
/// Support directions per part hull: each hull has at most this many vertices.
pub const HULL_DIRECTIONS: usize = 48;
/// At most every this-many-th vertex is searched for support points: the generator's
/// vertices are ~4 mm apart, so the hull loses under a millimetre and costs a third.
const HULL_STRIDE: usize = 3;
/// A skin part with fewer dominant vertices than this joins its parent's hull (the
/// generator's wing tips, ~250 vertices, join the forearm: 9 hulls per carcass, not 11).
const MIN_PART_VERTICES: usize = 300;
/// Guide walls: how many segments make the ring, how tall and thick they are.
const WALL_SEGMENTS: usize = 16;
const WALL_HEIGHT: f32 = 0.6;
const WALL_THICKNESS: f32 = 0.05;

/// Why a pile could not be simulated (the caller falls back to the height-field drop).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SettleError {
    #[error("carcass {body}: a vertex is not finite")]
    NonFinite { body: usize },
    #[error("carcass {body}: its vertices span no volume (flat or collapsed mesh), no hull")]
    Degenerate { body: usize },
    #[error("carcass {body}: the simulation diverged (non-finite pose)")]
    Diverged { body: usize },
    #[error("{plans} drop plans for {bodies} carcasses")]
    Mismatch { plans: usize, bodies: usize },
}

/// Every random choice about one carcass's drop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DropPlan {
    /// The resting mode the drop starts from (the carcass may roll out of it).
    pub mode: RestingMode,
    /// Orientation at release (resting mode, yaw and jitter, as the height-field drop).
    pub rotation: Quat,
    /// Release point in the plate plane.
    pub xy: Vec2,
    /// Free fall (m) between the carcass's bottom and what is under it at release.
    pub gap: f32,
}

impl DropPlan {
    /// Draws a resting mode (weights breast up / down / side), a yaw and the resting
    /// rotation's jitter, a release point uniform in the pile disc and a fall height.
    pub fn sample<R: Rng>(rng: &mut R, weights: [f32; 3], centre: Vec2, radius: f32) -> DropPlan {
        let wsum: f32 = weights.iter().sum::<f32>().max(1e-6);
        let u = rng.random_range(0.0..wsum);
        let mode = if u < weights[0] {
            RestingMode::BreastUp
        } else if u < weights[0] + weights[1] {
            RestingMode::BreastDown
        } else {
            RestingMode::Side
        };
        let yaw = rng.random_range(0.0..std::f32::consts::TAU);
        let rotation = pile::resting_rotation(rng, mode, yaw);
        let xy = pile::candidates(rng, centre, radius, 1)[0];
        let gap = rng.random_range(0.01..0.06);
        DropPlan {
            mode,
            rotation,
            xy,
            gap,
        }
    }
}

/// One carcass to drop: its oriented positions (lowest point at z = 0, xy bounding box
/// centred on the origin, as `pile::orient` returns them) and the skin part of each vertex.
pub struct BodyInput<'a> {
    pub local: &'a [Vec3],
    pub parts: &'a [u16],
}

/// Where the guide walls stand: a ring around `centre` (carcasses that slide off the pile
/// stop there instead of leaving the view).
#[derive(Clone, Copy, Debug)]
pub struct Fence {
    pub centre: Vec2,
    pub radius: f32,
}

/// The settled pile: one rigid motion per carcass (world = rotation * local + translation).
#[derive(Clone, Debug)]
pub struct Settled {
    pub motions: Vec<(Quat, Vec3)>,
    /// Steps simulated.
    pub steps: usize,
    /// True when every body was asleep before the step cap.
    pub asleep: bool,
    /// Fastest body at the end (m/s, centre of mass).
    pub max_speed: f32,
    /// Deepest hull-hull penetration among the final carcass contacts (m).
    pub max_penetration: f32,
    /// Wall time of hull building plus simulation.
    pub elapsed: Duration,
}

/// The skin part of each vertex: its dominant joint, with joints that dominate fewer than
/// [`MIN_PART_VERTICES`] vertices merged into their parent. A mesh without a skin is one part.
pub fn vertex_parts(mesh: &Mesh) -> Vec<u16> {
    let Some(skin) = &mesh.skin else {
        return vec![0; mesh.positions.len()];
    };
    let nj = skin.joints.len().max(1);
    let mut part: Vec<u16> = skin
        .vertex_joints
        .iter()
        .zip(&skin.vertex_weights)
        .map(|(j, w)| {
            let k = (0..4).fold(0, |b, i| if w[i] > w[b] { i } else { b });
            if (j[k] as usize) < nj {
                j[k]
            } else {
                0
            }
        })
        .collect();
    part.resize(mesh.positions.len(), 0);
    // Merge small parts upwards; parents are followed at most `nj` times (a cycle in a
    // malformed skin stops there instead of looping).
    for _ in 0..nj {
        let mut count = vec![0usize; nj];
        for &p in &part {
            count[p as usize] += 1;
        }
        let small = |j: usize| count[j] > 0 && count[j] < MIN_PART_VERTICES;
        let Some(j) = (0..nj).find(|&j| small(j) && skin.joints[j].parent.is_some()) else {
            break;
        };
        let parent = skin.joints[j].parent.unwrap_or(0).min(nj - 1) as u16;
        for p in part.iter_mut().filter(|p| **p as usize == j) {
            *p = parent;
        }
    }
    part
}

/// Unit directions spread evenly over the sphere (Fibonacci lattice).
fn directions(n: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let a = golden * i as f32;
            Vec3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// Whether a point set spans a volume: a tetrahedron of its extreme points has more than
/// 1 mm³ (rules out flat, linear and collapsed sets before the hull algorithm sees them).
fn spans_volume(pts: &[Vec3]) -> bool {
    let Some(&a) = pts.first() else {
        return false;
    };
    let far = |f: &dyn Fn(Vec3) -> f32| {
        pts.iter()
            .copied()
            .max_by(|x, y| f(*x).total_cmp(&f(*y)))
            .unwrap_or(a)
    };
    let b = far(&|p| (p - a).length_squared());
    let ab = (b - a).normalize_or_zero();
    let c = far(&|p| (p - a).reject_from_normalized(ab).length_squared());
    let n = (b - a).cross(c - a).normalize_or_zero();
    let d = far(&|p| (p - a).dot(n).abs());
    (b - a).cross(c - a).dot(d - a).abs() / 6.0 > 1e-9
}

/// Hull points of each part: the support point of the part's vertices in each of
/// [`HULL_DIRECTIONS`] directions (deduplicated), so a hull has at most that many vertices
/// whatever the mesh resolution. Parts whose points span no volume are left out.
fn part_hulls(body: usize, input: &BodyInput) -> Result<Vec<Vec<Vec3>>, SettleError> {
    if input.local.iter().any(|p| !p.is_finite()) {
        return Err(SettleError::NonFinite { body });
    }
    let dirs = directions(HULL_DIRECTIONS);
    let np = input
        .parts
        .iter()
        .map(|&p| p as usize + 1)
        .max()
        .unwrap_or(1);
    // best[part][dir] = (support value, vertex index)
    let mut best = vec![vec![(f32::NEG_INFINITY, usize::MAX); dirs.len()]; np];
    // Coarse meshes (a user's 8-vertex box) are searched whole.
    let stride = (input.local.len() / 4000).clamp(1, HULL_STRIDE);
    for (i, p) in input.local.iter().enumerate().step_by(stride) {
        let part = input.parts.get(i).copied().unwrap_or(0) as usize;
        for (d, b) in dirs.iter().zip(best[part].iter_mut()) {
            let s = p.dot(*d);
            if s > b.0 {
                *b = (s, i);
            }
        }
    }
    let mut hulls = Vec::new();
    for b in best {
        let mut idx: Vec<usize> = b
            .iter()
            .filter(|(_, i)| *i != usize::MAX)
            .map(|(_, i)| *i)
            .collect();
        idx.sort_unstable();
        idx.dedup();
        let pts: Vec<Vec3> = idx.iter().map(|&i| input.local[i]).collect();
        if pts.len() >= 4 && spans_volume(&pts) {
            hulls.push(pts);
        }
    }
    if hulls.is_empty() {
        return Err(SettleError::Degenerate { body });
    }
    Ok(hulls)
}

fn rv(v: Vec3) -> rapier3d::math::Vector {
    rapier3d::math::Vector::new(v.x, v.y, v.z)
}

/// The empty world: gravity, the fixed step and solver settings, and the plate with the
/// ring of guide walls on one fixed body (returned with the world).
fn stage(fence: Fence) -> (PhysicsWorld, RigidBodyHandle) {
    let mut world = PhysicsWorld::new();
    world.gravity = rv(Vec3::new(0.0, 0.0, -9.81));
    let ip = &mut world.integration_parameters;
    ip.dt = DT;
    ip.num_solver_iterations = SOLVER_ITERATIONS;
    ip.length_unit = LENGTH_UNIT;
    ip.contact_softness.natural_frequency = CONTACT_HZ;
    ip.static_contact_softness.natural_frequency = 2.0 * CONTACT_HZ;
    // The plate and the guide ring, on one fixed body.
    let ground = world.insert_body(RigidBodyBuilder::fixed());
    let plate = ColliderBuilder::halfspace(rapier3d::na::Unit::new_unchecked(rv(Vec3::Z)))
        .friction(FRICTION)
        .restitution(RESTITUTION);
    world.insert_collider(plate, Some(ground));
    let seg = std::f32::consts::TAU / WALL_SEGMENTS as f32;
    let half_len = (fence.radius + WALL_THICKNESS) * (seg * 0.5).tan() + WALL_THICKNESS;
    for i in 0..WALL_SEGMENTS {
        let a = seg * i as f32;
        let r = fence.radius + WALL_THICKNESS * 0.5;
        let c = fence.centre + Vec2::new(a.cos(), a.sin()) * r;
        let wall = ColliderBuilder::cuboid(WALL_THICKNESS * 0.5, half_len, WALL_HEIGHT * 0.5)
            .translation(rv(Vec3::new(c.x, c.y, WALL_HEIGHT * 0.5)))
            .rotation(rv(Vec3::new(0.0, 0.0, a)))
            .friction(FRICTION * 0.5)
            .restitution(RESTITUTION);
        world.insert_collider(wall, Some(ground));
    }
    (world, ground)
}

/// Steps `world` until every body of `handles` sleeps or [`MAX_STEPS`] are done:
/// (steps taken, whether all slept).
fn step_until_asleep(world: &mut PhysicsWorld, handles: &[RigidBodyHandle]) -> (usize, bool) {
    let mut steps = 0;
    let mut asleep = false;
    while steps < MAX_STEPS {
        world.step();
        steps += 1;
        if handles.iter().all(|h| world.bodies[*h].is_sleeping()) {
            asleep = true;
            break;
        }
    }
    (steps, asleep)
}

/// Drops `bodies` (in order) with their `plans`' release points and gaps, inside `fence`,
/// and steps until the pile is at rest.
pub fn settle(
    bodies: &[BodyInput],
    plans: &[DropPlan],
    fence: Fence,
) -> Result<Settled, SettleError> {
    let t0 = Instant::now();
    if plans.len() != bodies.len() {
        return Err(SettleError::Mismatch {
            plans: plans.len(),
            bodies: bodies.len(),
        });
    }
    use rayon::prelude::*;
    let hulls: Vec<Vec<Vec<Vec3>>> = bodies
        .par_iter()
        .enumerate()
        .map(|(k, b)| part_hulls(k, b))
        .collect::<Result<_, _>>()?;
    let (mut world, ground) = stage(fence);
    // Release heights: each carcass starts `gap` above the highest carcass released before
    // it whose footprint (xy box) overlaps its own, so the pile forms in one short fall.
    let mut placed: Vec<(Vec2, Vec2, f32)> = Vec::with_capacity(bodies.len());
    let mut handles: Vec<RigidBodyHandle> = Vec::with_capacity(bodies.len());
    for (parts, plan) in hulls.iter().zip(plans) {
        let (lo, hi) = parts.iter().flatten().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        let (blo, bhi) = (lo.truncate() + plan.xy, hi.truncate() + plan.xy);
        let under = placed
            .iter()
            .filter(|(l, h, _)| l.x < bhi.x && blo.x < h.x && l.y < bhi.y && blo.y < h.y)
            .map(|(_, _, top)| *top)
            .fold(0.0f32, f32::max);
        // The hulls' lowest point can sit a little above the mesh's (support sampling).
        let z = under + plan.gap - lo.z.min(0.0);
        placed.push((blo, bhi, z + hi.z));
        let rb = RigidBodyBuilder::dynamic()
            .translation(rv(Vec3::new(plan.xy.x, plan.xy.y, z)))
            .linear_damping(LINEAR_DAMPING)
            .angular_damping(ANGULAR_DAMPING);
        let h = world.insert_body(rb);
        world.bodies[h].activation_mut().time_until_sleep = TIME_UNTIL_SLEEP;
        for pts in parts {
            let p: Vec<_> = pts.iter().map(|&v| rv(v)).collect();
            // `spans_volume` ruled out the inputs the hull algorithm rejects; a refusal
            // anyway drops that part (the body keeps its others, or fails below).
            if let Some(c) = ColliderBuilder::convex_hull(&p) {
                let c = c
                    .density(MEAT_DENSITY)
                    .friction(FRICTION)
                    .friction_combine_rule(CoefficientCombineRule::Average)
                    .restitution(RESTITUTION);
                world.insert_collider(c, Some(h));
            }
        }
        handles.push(h);
    }
    for (k, h) in handles.iter().enumerate() {
        if world.bodies[*h].colliders().is_empty() {
            return Err(SettleError::Degenerate { body: k });
        }
    }
    let (steps, asleep) = step_until_asleep(&mut world, &handles);
    let mut motions = Vec::with_capacity(handles.len());
    let mut max_speed = 0.0f32;
    for (k, h) in handles.iter().enumerate() {
        let b = &world.bodies[*h];
        let pose = b.position();
        let q = Quat::from_array(pose.rotation.to_array());
        let t = Vec3::from_array(pose.translation.to_array());
        if !q.is_finite() || !t.is_finite() {
            return Err(SettleError::Diverged { body: k });
        }
        max_speed = max_speed.max(Vec3::from_array(b.linvel().to_array()).length());
        motions.push((q.normalize(), t));
    }
    let dynamic = |c| {
        world
            .colliders
            .get(c)
            .and_then(|c| c.parent())
            .is_some_and(|p| p != ground)
    };
    let max_penetration = world
        .narrow_phase
        .contact_pairs()
        .filter(|p| dynamic(p.collider1) && dynamic(p.collider2))
        .filter_map(|p| p.find_deepest_contact().map(|(_, c)| -c.dist))
        .fold(0.0f32, f32::max);
    Ok(Settled {
        motions,
        steps,
        asleep,
        max_speed,
        max_penetration,
        elapsed: t0.elapsed(),
    })
}

/// A pile settled for rendering: each carcass's world positions, normals and the resting
/// mode it ended in, with the simulation's report.
pub struct SettledPile {
    pub carcasses: Vec<(Vec<Vec3>, Vec<Vec3>, RestingMode)>,
    pub report: Settled,
}

/// Guide walls stand this far outside the release disc: a carcass sliding off the pile
/// stops about one carcass width from where the pile was aimed.
pub const FENCE_MARGIN: f32 = 0.12;

/// Drops posed carcasses (positions and normals in the carcass frame, as `pose_mesh` gives
/// them; `parts` from [`vertex_parts`] per carcass) into a pile in the disc (`centre`,
/// `radius`). Draws one [`DropPlan`] per carcass from `rng`, in carcass order, then
/// orients, settles and moves the meshes.
pub fn drop_pile<R: Rng>(
    rng: &mut R,
    weights: [f32; 3],
    centre: Vec2,
    radius: f32,
    posed: &[(Vec<Vec3>, Vec<Vec3>)],
    parts: &[&[u16]],
) -> Result<SettledPile, SettleError> {
    use rayon::prelude::*;
    if parts.len() != posed.len() {
        return Err(SettleError::Mismatch {
            plans: parts.len(),
            bodies: posed.len(),
        });
    }
    let plans: Vec<DropPlan> = (0..posed.len())
        .map(|_| DropPlan::sample(rng, weights, centre, radius))
        .collect();
    let oriented: Vec<(Vec<Vec3>, Vec<Vec3>)> = posed
        .par_iter()
        .zip(&plans)
        .map(|((p, n), plan)| pile::orient(p, n, plan.rotation))
        .collect();
    let inputs: Vec<BodyInput> = oriented
        .iter()
        .zip(parts)
        .map(|((p, _), parts)| BodyInput { local: p, parts })
        .collect();
    let fence = Fence {
        centre,
        radius: radius + FENCE_MARGIN,
    };
    let report = settle(&inputs, &plans, fence)?;
    let carcasses = oriented
        .into_par_iter()
        .zip(&plans)
        .zip(&report.motions)
        .map(|(((p, n), plan), &(q, t))| {
            (
                p.into_iter().map(|v| q * v + t).collect(),
                n.into_iter().map(|v| q * v).collect(),
                settled_mode(plan.rotation, q),
            )
        })
        .collect();
    Ok(SettledPile { carcasses, report })
}

/// The resting mode a settled carcass shows: where its breast (+z of the carcass frame,
/// turned by the drop rotation and then the settled motion) points.
pub fn settled_mode(drop: Quat, motion: Quat) -> RestingMode {
    let up = (motion * drop * Vec3::Z).z;
    if up > 0.5 {
        RestingMode::BreastUp
    } else if up < -0.5 {
        RestingMode::BreastDown
    } else {
        RestingMode::Side
    }
}

#[cfg(test)]
mod tests {
    use std::collections::{HashMap, HashSet};

    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::render::asset;
    use crate::render::pile::HeightField;
    use crate::render::skin::{pose_mesh, Pose, PoseRanges};
    use crate::render::{render_sample, RenderOptions};
    use crate::util::hash::{fnv, FNV_OFFSET};

    /// FNV of the pixels, id buffer and labels of a few dense images.
    fn render_hash(o: &RenderOptions) -> u64 {
        let mut h = FNV_OFFSET;
        for i in 0..3 {
            let s = render_sample(o, 5, i).unwrap();
            h = fnv(h, s.image.as_raw());
            h = fnv(
                h,
                &s.ids
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect::<Vec<_>>(),
            );
            h = fnv(h, format!("{:?}", s.instances).as_bytes());
        }
        h
    }

    fn dense(size: u32) -> RenderOptions {
        let mut o = RenderOptions::synthetic(size);
        o.carcasses = [6, 10];
        o.density = [0.8, 1.0];
        o
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn physics_off_renders_exactly_what_the_height_field_drop_rendered() {
        // Recorded from the renderer before the physics group existed (main at 4573f5e):
        // with the flag off every pixel, id and label must stay as it was.
        assert_eq!(render_hash(&dense(64)), 0x4e0b_f933_f470_fe0b);
    }

    #[test]
    fn physics_on_is_deterministic_and_changes_the_pile() {
        let mut o = dense(48);
        o.randomize.physics = true;
        let a = render_hash(&o);
        assert_eq!(a, render_hash(&o));
        o.randomize.physics = false;
        assert_ne!(a, render_hash(&o));
    }

    /// A solid box as a dense point cloud (one part).
    fn cuboid(h: Vec3) -> Vec<Vec3> {
        let mut v = Vec::new();
        for i in 0..=8 {
            for j in 0..=8 {
                for k in 0..=4 {
                    let f = Vec3::new(i as f32 / 4.0 - 1.0, j as f32 / 4.0 - 1.0, k as f32 / 2.0);
                    v.push(f * h);
                }
            }
        }
        v
    }

    fn plan(xy: Vec2) -> DropPlan {
        DropPlan {
            mode: RestingMode::BreastUp,
            rotation: Quat::IDENTITY,
            xy,
            gap: 0.03,
        }
    }

    #[test]
    fn boxes_stack_settle_and_do_not_interpenetrate_and_runs_repeat_exactly() {
        let b = cuboid(Vec3::new(0.12, 0.07, 0.05));
        let parts = vec![0u16; b.len()];
        let bodies: Vec<BodyInput> = (0..5)
            .map(|_| BodyInput {
                local: &b,
                parts: &parts,
            })
            .collect();
        let plans: Vec<DropPlan> = (0..5)
            .map(|k| plan(Vec2::new(0.02 * k as f32, 0.01 * k as f32)))
            .collect();
        let fence = Fence {
            centre: Vec2::ZERO,
            radius: 0.5,
        };
        let s = settle(&bodies, &plans, fence).unwrap();
        assert!(s.asleep, "not asleep after {} steps", s.steps);
        assert!(s.max_speed < 0.02, "still moving at {} m/s", s.max_speed);
        // 3.5 kg boxes, five high: heavier than any carcass pile presses.
        assert!(
            s.max_penetration < 0.008,
            "penetration {}",
            s.max_penetration
        );
        let bottoms: Vec<f32> = s
            .motions
            .iter()
            .map(|&(q, t)| {
                b.iter()
                    .map(|&p| (q * p + t).z)
                    .fold(f32::INFINITY, f32::min)
            })
            .collect();
        assert!(
            bottoms.iter().all(|&z| z > -0.003),
            "below the plate: {bottoms:?}"
        );
        // Released over each other: they stack (some rest on others), not all on the plate.
        assert!(
            bottoms.iter().any(|&z| z > 0.04),
            "no stacking: {bottoms:?}"
        );
        let again = settle(&bodies, &plans, fence).unwrap();
        assert_eq!(s.motions, again.motions);
        assert_eq!(s.steps, again.steps);
    }

    #[test]
    fn flat_or_broken_meshes_are_errors_not_panics() {
        let b = cuboid(Vec3::new(0.1, 0.05, 0.04));
        let flat: Vec<Vec3> = b.iter().map(|p| Vec3::new(p.x, p.y, 0.0)).collect();
        let line: Vec<Vec3> = b.iter().map(|p| Vec3::new(p.x, 0.0, 0.0)).collect();
        let mut nan = b.clone();
        nan[3].y = f32::NAN;
        let parts = vec![0u16; b.len()];
        let fence = Fence {
            centre: Vec2::ZERO,
            radius: 0.5,
        };
        for (bad, want) in [
            (&flat, SettleError::Degenerate { body: 1 }),
            (&line, SettleError::Degenerate { body: 1 }),
            (&nan, SettleError::NonFinite { body: 1 }),
            (&Vec::new(), SettleError::Degenerate { body: 1 }),
        ] {
            let bodies = [
                BodyInput {
                    local: &b,
                    parts: &parts,
                },
                BodyInput {
                    local: bad,
                    parts: &parts,
                },
            ];
            let plans = [plan(Vec2::ZERO), plan(Vec2::X * 0.2)];
            assert_eq!(settle(&bodies, &plans, fence).unwrap_err(), want);
        }
        let bodies = [BodyInput {
            local: &b,
            parts: &parts,
        }];
        assert!(matches!(
            settle(&bodies, &[], fence),
            Err(SettleError::Mismatch { .. })
        ));
    }

    #[test]
    fn a_flat_user_mesh_falls_back_to_the_height_field_drop() {
        // A 20 cm rod of zero-area triangles: posing moves its vertices along their normals
        // (all +z here), so it stays planar, has no hull, and the pile is dropped on the
        // height field instead: the image still renders.
        let positions: Vec<Vec3> = (0..4)
            .map(|i| Vec3::new(i as f32 * 0.066 - 0.1, 0.0, 0.0))
            .collect();
        let indices = vec![0, 1, 2, 1, 2, 3];
        let normals = Mesh::compute_normals(&positions, &indices);
        assert!(matches!(
            part_hulls(
                0,
                &BodyInput {
                    local: &positions,
                    parts: &[0; 4]
                }
            ),
            Err(SettleError::Degenerate { body: 0 })
        ));
        let m = Mesh {
            positions,
            normals,
            indices,
            skin: None,
        };
        let path = std::env::temp_dir().join(format!("ct-sheet-{}.glb", std::process::id()));
        std::fs::write(&path, crate::render::glb::to_glb(&m).unwrap()).unwrap();
        let mut o = RenderOptions::synthetic(48);
        o.carcasses = [2, 3];
        o.carcass = Some(path.clone());
        o.randomize.physics = true;
        let on = render_sample(&o, 0, 0).unwrap();
        let _ = std::fs::remove_file(path);
        assert_eq!(on.image.dimensions(), (48, 48));
        assert_eq!(on.timings.physics, Duration::ZERO);
    }

    /// Solid voxels (cell `c`) of a closed mesh: inside/outside by the parity of the
    /// surface crossings along each vertical column.
    fn solid(pos: &[Vec3], idx: &[u32], c: f32) -> HashSet<(i32, i32, i32)> {
        let mut cols: HashMap<(i32, i32), Vec<f32>> = HashMap::new();
        for t in idx.chunks_exact(3) {
            let [a, b, d] = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
            let (lo, hi) = (a.min(b).min(d), a.max(b).max(d));
            let area = (b.x - a.x) * (d.y - a.y) - (d.x - a.x) * (b.y - a.y);
            if area.abs() < 1e-12 {
                continue;
            }
            for i in (lo.x / c).floor() as i32..=(hi.x / c).ceil() as i32 {
                for j in (lo.y / c).floor() as i32..=(hi.y / c).ceil() as i32 {
                    // Column centres nudged off the grid so no column hits an edge exactly.
                    let (x, y) = ((i as f32 + 0.5) * c + 1.3e-5, (j as f32 + 0.5) * c + 0.7e-5);
                    let w1 = ((x - a.x) * (d.y - a.y) - (d.x - a.x) * (y - a.y)) / area;
                    let w2 = ((b.x - a.x) * (y - a.y) - (x - a.x) * (b.y - a.y)) / area;
                    if w1 >= 0.0 && w2 >= 0.0 && w1 + w2 <= 1.0 {
                        let z = a.z + w1 * (b.z - a.z) + w2 * (d.z - a.z);
                        cols.entry((i, j)).or_default().push(z);
                    }
                }
            }
        }
        let mut out = HashSet::new();
        for ((i, j), mut zs) in cols {
            if zs.len() % 2 != 0 {
                continue;
            }
            zs.sort_by(f32::total_cmp);
            for p in zs.chunks_exact(2) {
                for k in (p[0] / c).round() as i32..(p[1] / c).round() as i32 {
                    out.insert((i, j, k));
                }
            }
        }
        out
    }

    /// Fraction of the carcasses' solid volume that lies inside another carcass.
    fn overlap(meshes: &[Vec<Vec3>], idx: &[u32]) -> f64 {
        let solids: Vec<_> = meshes.iter().map(|m| solid(m, idx, 0.004)).collect();
        let total: usize = solids.iter().map(|s| s.len()).sum();
        let mut shared = 0;
        for (a, sa) in solids.iter().enumerate() {
            for sb in &solids[a + 1..] {
                shared += sa.intersection(sb).count();
            }
        }
        2.0 * shared as f64 / total.max(1) as f64
    }

    #[test]
    fn dense_carcass_piles_settle_stacked_inside_the_fence_with_little_overlap() {
        const W: [f32; 3] = [0.5, 0.3, 0.2];
        let asset = asset::asset(None).unwrap();
        let parts = vertex_parts(&asset.mesh);
        let nparts = parts.iter().collect::<HashSet<_>>().len();
        let t = Instant::now();
        let hulls = part_hulls(
            0,
            &BodyInput {
                local: &asset.mesh.positions,
                parts: &parts,
            },
        )
        .unwrap();
        println!(
            "{} vertices, {} parts, hull points {:?}, hulls of one carcass in {:.2} ms",
            asset.mesh.positions.len(),
            nparts,
            hulls.iter().map(|h| h.len()).collect::<Vec<_>>(),
            t.elapsed().as_secs_f64() * 1e3
        );
        assert!(nparts >= 5, "only {nparts} hull parts");

        let (centre, n) = (Vec2::new(0.05, -0.03), 12);
        // The layout's density-1 disc for 12 carcasses (scene::PileLayout).
        let radius = (0.055 * n as f32 * 0.45 / std::f32::consts::PI).sqrt();
        let mut worst_phys: f64 = 0.0;
        let mut worst_hf: f64 = 0.0;
        for seed in 0..2u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let posed: Vec<_> = (0..n)
                .map(|_| pose_mesh(&asset.mesh, &Pose::sample(&mut rng, &PoseRanges::default())))
                .collect();
            let part_refs: Vec<&[u16]> = vec![&parts; n];
            let pile = drop_pile(&mut rng.clone(), W, centre, radius, &posed, &part_refs).unwrap();
            let r = &pile.report;
            println!(
                "seed {seed}: {} steps, asleep {}, {:.1} ms, max speed {:.4} m/s, max hull penetration {:.2} mm",
                r.steps,
                r.asleep,
                r.elapsed.as_secs_f64() * 1e3,
                r.max_speed,
                r.max_penetration * 1e3
            );
            assert!(r.max_speed < 0.05, "still moving at {} m/s", r.max_speed);
            assert!(
                r.max_penetration < 0.005,
                "hulls interpenetrate by {}",
                r.max_penetration
            );
            let mut stacked = 0;
            for (p, _, _) in &pile.carcasses {
                let bottom = p.iter().map(|v| v.z).fold(f32::INFINITY, f32::min);
                // Soft contacts under the pile's weight plus the hull's support sampling.
                assert!(bottom > -0.008, "a carcass sinks {bottom} m into the plate");
                stacked += (bottom > 0.03) as usize;
                let c = p.iter().copied().sum::<Vec3>() / p.len() as f32;
                assert!(
                    (c.truncate() - centre).length() < radius + FENCE_MARGIN,
                    "a carcass left the fence: centre at {c}"
                );
            }
            assert!(
                stacked >= 2,
                "only {stacked} of {n} carcasses rest on others"
            );
            let phys: Vec<Vec<Vec3>> = pile.carcasses.iter().map(|c| c.0.clone()).collect();
            // The height-field drop of the same poses, orientations and spots.
            let mut hf = HeightField::around(centre, radius + 0.45, 0.004);
            // drop_pile draws all plans first, in carcass order: the same draws here.
            let mut prng = rng.clone();
            let plans: Vec<DropPlan> = (0..n)
                .map(|_| DropPlan::sample(&mut prng, W, centre, radius))
                .collect();
            let hfm: Vec<Vec<Vec3>> = posed
                .iter()
                .zip(&plans)
                .map(|((p, nn), plan)| {
                    let (l, mut nor) = pile::orient(p, nn, plan.rotation);
                    pile::drop_one(&mut hf, &l, &mut nor, &[plan.xy])
                })
                .collect();
            let (op, oh) = (
                overlap(&phys, &asset.mesh.indices),
                overlap(&hfm, &asset.mesh.indices),
            );
            println!(
                "seed {seed}: voxel overlap physics {:.4}, height field {:.4}",
                op, oh
            );
            worst_phys = worst_phys.max(op);
            worst_hf = worst_hf.max(oh);
        }
        // Both are small: the height field never lowers a carcass into what is below (its
        // overlap is the drape's smoothing); the physics' is mesh outside its part hulls.
        assert!(worst_phys < 0.01, "physics piles overlap by {worst_phys}");
        assert!(worst_hf < 0.01, "height-field piles overlap by {worst_hf}");
    }
}
