//! Per-instance carcass shape: a pose (wings folded…spread, legs bent…splayed) applied by
//! linear-blend skinning, per-part scale and left/right asymmetry, a missing wing tip now
//! and then, and low-frequency surface displacement along the normal.
//!
//! Joints are looked up by the names the generator writes (`carcass::JOINT_NAMES`), so a
//! user .glb that uses them poses too; unknown joints stay at rest and rigid meshes only
//! get scale and displacement. Joint transforms are rotations/scales about each joint's
//! rest pivot, composed down the hierarchy: G_j = G_parent · T(p_j) R_j S_j T(-p_j).

use glam::{Mat3, Mat4, Quat, Vec3};
use rand::Rng;

use super::mesh::Mesh;

/// Everything random about one carcass's shape. Angles in radians; index 0 = left side.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    /// Uniform size factor (bird weight class).
    pub scale: f32,
    /// Body (breast width/depth) anisotropic scale.
    pub body_scale: Vec3,
    /// Wing spread about the shoulder (+ = away from the body).
    pub wing_spread: [f32; 2],
    /// Elbow and wrist opening (+ = unfolded).
    pub wing_open: [f32; 2],
    /// Wing droop about the body axis (+ = tip down).
    pub wing_droop: [f32; 2],
    /// Leg splay about the hip (+ = hocks outwards).
    pub leg_splay: [f32; 2],
    /// Leg lift about the hip's lateral axis (+ = hocks up, towards the breast side).
    pub leg_lift: [f32; 2],
    /// Knee bend (+ = drumstick folds towards the thigh).
    pub knee_bend: [f32; 2],
    /// Thigh, drumstick and wing scale per side.
    pub thigh_scale: [f32; 2],
    pub drum_scale: [f32; 2],
    pub wing_scale: [f32; 2],
    /// Wing tip removed (damaged in processing).
    pub missing_tip: [bool; 2],
    /// Displacement amplitude (m) and its random wave set.
    pub displacement: f32,
    pub waves: Vec<(Vec3, f32, f32)>,
}

/// Ranges for [`Pose::sample`]; presets differ in them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseRanges {
    pub scale: [f32; 2],
    pub asymmetry: f32,
    pub wing_spread: [f32; 2],
    pub leg_splay: [f32; 2],
    pub knee_bend: [f32; 2],
    pub displacement_mm: [f32; 2],
    pub p_missing_tip: f32,
}

impl Default for PoseRanges {
    fn default() -> Self {
        PoseRanges {
            scale: [0.88, 1.12],
            asymmetry: 0.08,
            wing_spread: [-0.2, 0.5],
            leg_splay: [-0.1, 0.4],
            knee_bend: [-0.25, 0.35],
            displacement_mm: [1.0, 3.5],
            p_missing_tip: 0.06,
        }
    }
}

fn uni<R: Rng>(rng: &mut R, r: [f32; 2]) -> f32 {
    if r[1] > r[0] {
        rng.random_range(r[0]..r[1])
    } else {
        r[0]
    }
}

impl Pose {
    /// The rest pose (identity skinning, no displacement).
    pub fn rest() -> Pose {
        Pose {
            scale: 1.0,
            body_scale: Vec3::ONE,
            wing_spread: [0.0; 2],
            wing_open: [0.0; 2],
            wing_droop: [0.0; 2],
            leg_splay: [0.0; 2],
            leg_lift: [0.0; 2],
            knee_bend: [0.0; 2],
            thigh_scale: [1.0; 2],
            drum_scale: [1.0; 2],
            wing_scale: [1.0; 2],
            missing_tip: [false; 2],
            displacement: 0.0,
            waves: Vec::new(),
        }
    }

    pub fn sample<R: Rng>(rng: &mut R, r: &PoseRanges) -> Pose {
        // One shared value per bird plus a small per-side deviation gives asymmetry
        // without making left and right independent (real birds are roughly symmetric).
        let a = r.asymmetry;
        let pair = |rng: &mut R, range: [f32; 2], dev: f32| {
            let c = uni(rng, range);
            [
                c + rng.random_range(-dev..=dev),
                c + rng.random_range(-dev..=dev),
            ]
        };
        let wing_spread = pair(rng, r.wing_spread, 0.25);
        let wing_open = pair(rng, [-0.3, 0.35], 0.2);
        let wing_droop = pair(rng, [-0.2, 0.35], 0.15);
        let leg_splay = pair(rng, r.leg_splay, 0.15);
        let leg_lift = pair(rng, [-0.25, 0.25], 0.1);
        let knee_bend = pair(rng, r.knee_bend, 0.12);
        let thigh_scale = pair(rng, [0.92, 1.08], a);
        let drum_scale = pair(rng, [0.92, 1.08], a);
        let wing_scale = pair(rng, [0.9, 1.1], a);
        let missing_tip = [
            rng.random_bool(r.p_missing_tip as f64),
            rng.random_bool(r.p_missing_tip as f64),
        ];
        let body_scale = Vec3::new(
            rng.random_range(0.93..1.07),
            rng.random_range(0.9..1.1),
            rng.random_range(0.88..1.08),
        );
        let displacement = uni(rng, r.displacement_mm) * 1e-3;
        let waves = (0..6)
            .map(|k| {
                let dir = Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
                .normalize_or(Vec3::X);
                // Wavelengths 4-15 cm: lumps, not noise (follicles are shading detail).
                let freq = std::f32::consts::TAU / rng.random_range(0.04..0.15);
                let amp = 1.0 / (1.0 + k as f32 * 0.4);
                (
                    dir * freq,
                    rng.random_range(0.0..std::f32::consts::TAU),
                    amp,
                )
            })
            .collect();
        Pose {
            scale: uni(rng, r.scale),
            body_scale,
            wing_spread,
            wing_open,
            wing_droop,
            leg_splay,
            leg_lift,
            knee_bend,
            thigh_scale,
            drum_scale,
            wing_scale,
            missing_tip,
            displacement,
            waves,
        }
    }

    fn displacement_at(&self, p: Vec3) -> f32 {
        if self.waves.is_empty() {
            return 0.0;
        }
        let norm: f32 = self.waves.iter().map(|w| w.2).sum();
        let s: f32 = self
            .waves
            .iter()
            .map(|(f, ph, a)| a * (f.dot(p) + ph).sin())
            .sum();
        self.displacement * s / norm
    }
}

/// Local transform of joint `name` with pivot `p` under `pose`.
fn joint_local(name: &str, p: Vec3, pose: &Pose, pivots: &dyn Fn(&str) -> Option<Vec3>) -> Mat4 {
    let (side, s) = if name.ends_with("_L") {
        (0usize, 1.0f32)
    } else {
        (1usize, -1.0f32)
    };
    let around = |m: Mat4| Mat4::from_translation(p) * m * Mat4::from_translation(-p);
    let suffix = if side == 0 { "_L" } else { "_R" };
    let child_dir = |child: &str, fallback: Vec3| {
        pivots(&format!("{child}{suffix}"))
            .map(|c| (c - p).normalize_or(fallback))
            .unwrap_or(fallback)
    };
    match name.trim_end_matches("_L").trim_end_matches("_R") {
        "body" => around(Mat4::from_scale(pose.body_scale)),
        "hip" => {
            let r = Quat::from_rotation_z(-s * pose.leg_splay[side])
                * Quat::from_rotation_y(-pose.leg_lift[side]);
            around(Mat4::from_quat(r) * Mat4::from_scale(Vec3::splat(pose.thigh_scale[side])))
        }
        "knee" => {
            // Bend about the axis normal to the thigh/drumstick plane.
            let thigh = pivots(&format!("hip{suffix}"))
                .map(|h| p - h)
                .unwrap_or(Vec3::X);
            let drum = Vec3::new(-1.0, 0.0, 0.3);
            let axis = thigh.cross(drum).normalize_or(Vec3::Y * s);
            let r = Quat::from_axis_angle(axis, pose.knee_bend[side]);
            around(Mat4::from_quat(r) * Mat4::from_scale(Vec3::splat(pose.drum_scale[side])))
        }
        "shoulder" => {
            let axis = child_dir("elbow", Vec3::Y * s);
            let r = Quat::from_rotation_z(-s * pose.wing_spread[side])
                * Quat::from_axis_angle(Vec3::X, -s * pose.wing_droop[side] * 0.5)
                * Quat::from_axis_angle(axis, pose.wing_droop[side] * 0.3);
            around(Mat4::from_quat(r) * Mat4::from_scale(Vec3::splat(pose.wing_scale[side])))
        }
        "elbow" => around(Mat4::from_quat(Quat::from_rotation_z(
            s * pose.wing_open[side],
        ))),
        "wrist" => {
            let sc = if pose.missing_tip[side] { 0.05 } else { 1.0 };
            around(
                Mat4::from_quat(Quat::from_rotation_z(-s * pose.wing_open[side] * 0.8))
                    * Mat4::from_scale(Vec3::splat(sc)),
            )
        }
        _ => Mat4::IDENTITY,
    }
}

/// Skins `mesh` with `pose`: returns posed positions and normals in the carcass frame
/// (before the resting-mode rotation), with the uniform scale applied.
pub fn pose_mesh(mesh: &Mesh, pose: &Pose) -> (Vec<Vec3>, Vec<Vec3>) {
    // Displace in rest space first, so the lumps ride along with the skin.
    let rest: Vec<Vec3> = mesh
        .positions
        .iter()
        .zip(&mesh.normals)
        .map(|(&p, &n)| p + n * pose.displacement_at(p))
        .collect();
    let global = Mat4::from_scale(Vec3::splat(pose.scale));
    let Some(skin) = &mesh.skin else {
        let nm = Mat3::from_mat4(global);
        return (
            rest.iter().map(|&p| global.transform_point3(p)).collect(),
            mesh.normals
                .iter()
                .map(|&n| (nm * n).normalize_or(n))
                .collect(),
        );
    };
    let pivots = |name: &str| skin.joints.iter().find(|j| j.name == name).map(|j| j.pivot);
    // Joints may be listed in any order: resolve parents first (depth-limited).
    let mut g: Vec<Option<Mat4>> = vec![None; skin.joints.len()];
    for _ in 0..skin.joints.len() {
        for (k, j) in skin.joints.iter().enumerate() {
            if g[k].is_some() {
                continue;
            }
            let parent = match j.parent {
                None => Some(global),
                Some(p) => g[p],
            };
            if let Some(pm) = parent {
                g[k] = Some(pm * joint_local(&j.name, j.pivot, pose, &pivots));
            }
        }
    }
    let g: Vec<Mat4> = g.into_iter().map(|m| m.unwrap_or(global)).collect();
    let gn: Vec<Mat3> = g.iter().map(|m| Mat3::from_mat4(*m)).collect();
    let mut pos = Vec::with_capacity(rest.len());
    let mut nor = Vec::with_capacity(rest.len());
    for (i, &p) in rest.iter().enumerate() {
        let (js, ws) = (skin.vertex_joints[i], skin.vertex_weights[i]);
        let mut pp = Vec3::ZERO;
        let mut nn = Vec3::ZERO;
        for k in 0..4 {
            if ws[k] > 0.0 {
                let j = js[k] as usize;
                pp += g[j].transform_point3(p) * ws[k];
                nn += (gn[j] * mesh.normals[i]) * ws[k];
            }
        }
        pos.push(pp);
        nor.push(nn.normalize_or(mesh.normals[i]));
    }
    (pos, nor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::carcass;
    use rand::SeedableRng;

    #[test]
    fn rest_pose_is_identity_and_spread_moves_wings_out() {
        let mesh = carcass::generate(0.008);
        let (p, _) = pose_mesh(&mesh, &Pose::rest());
        for (a, b) in p.iter().zip(&mesh.positions) {
            assert!((*a - *b).length() < 1e-5);
        }
        let mut spread = Pose::rest();
        spread.wing_spread = [0.5, 0.5];
        let (q, _) = pose_mesh(&mesh, &spread);
        let skin = mesh.skin.as_ref().unwrap();
        // Vertices dominated by the left wrist joint (7) move to larger +y, right (10) to -y.
        let mut moved = [0.0f32; 2];
        for (i, j) in skin.vertex_joints.iter().enumerate() {
            if skin.vertex_weights[i][0] > 0.9 && j[0] == 7 {
                moved[0] += q[i].y - p[i].y;
            }
            if skin.vertex_weights[i][0] > 0.9 && j[0] == 10 {
                moved[1] += q[i].y - p[i].y;
            }
        }
        assert!(moved[0] > 0.0 && moved[1] < 0.0, "{moved:?}");
    }

    #[test]
    fn sampled_pose_is_deterministic_and_finite() {
        let mesh = carcass::generate(0.008);
        let r = PoseRanges::default();
        let a = Pose::sample(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &r);
        let b = Pose::sample(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &r);
        assert_eq!(a, b);
        let (p, n) = pose_mesh(&mesh, &a);
        assert!(p.iter().chain(&n).all(|v| v.is_finite()));
    }
}
