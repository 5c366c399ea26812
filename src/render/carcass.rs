//! Procedural broiler carcass: a smooth-blended signed-distance body (back, breast lobes,
//! keel, neck stump, tail), thighs, drumsticks ending in hock knobs (feet removed) and
//! three-segment wings, meshed by surface nets on a 4 mm grid, with linear-blend bone
//! weights for hips, knees, shoulders, elbows and wrists.
//!
//! No permissively licensed carcass scan exists (`shared/notes/renderer.md`), so the asset
//! is generated here and written to `assets/carcass.glb` by [`write_default_asset`]; the
//! renderer embeds that file. Units are metres. The carcass frame is: +x towards the neck,
//! +y to the bird's left, +z out of the breast (breast-up rest pose, back at -z).

use glam::Vec3;
use rayon::prelude::*;

use super::mesh::{Joint, Mesh, Skin};

/// One smooth primitive of the SDF, bound to one bone (index into [`JOINT_NAMES`]).
#[derive(Clone, Copy, Debug)]
enum Prim {
    /// Ellipsoid: centre, radii.
    Ellipsoid(Vec3, Vec3),
    /// Round cone from `a` (radius `ra`) to `b` (radius `rb`).
    Cone(Vec3, Vec3, f32, f32),
}

/// Joint names; the pose code in `skin.rs` looks joints up by these names.
pub const JOINT_NAMES: [&str; 11] = [
    "body",
    "hip_L",
    "knee_L",
    "hip_R",
    "knee_R",
    "shoulder_L",
    "elbow_L",
    "wrist_L",
    "shoulder_R",
    "elbow_R",
    "wrist_R",
];

/// Parent of each joint in [`JOINT_NAMES`] (body is the root).
const JOINT_PARENTS: [Option<usize>; 11] = [
    None,
    Some(0),
    Some(1),
    Some(0),
    Some(3),
    Some(0),
    Some(5),
    Some(6),
    Some(0),
    Some(8),
    Some(9),
];

/// Key anatomical points of one side (`s` = +1 left, -1 right).
struct Side {
    hip: Vec3,
    knee: Vec3,
    hock: Vec3,
    shoulder: Vec3,
    elbow: Vec3,
    wrist: Vec3,
    tip: Vec3,
}

fn side(s: f32) -> Side {
    Side {
        hip: Vec3::new(-0.032, s * 0.048, -0.008),
        knee: Vec3::new(0.004, s * 0.072, 0.032),
        hock: Vec3::new(-0.112, s * 0.036, 0.056),
        shoulder: Vec3::new(0.068, s * 0.058, 0.004),
        elbow: Vec3::new(0.012, s * 0.098, -0.018),
        wrist: Vec3::new(0.082, s * 0.104, -0.030),
        tip: Vec3::new(0.030, s * 0.115, -0.045),
    }
}

/// Joint pivots (rest pose) in joint order.
pub fn joint_pivots() -> [Vec3; 11] {
    let (l, r) = (side(1.0), side(-1.0));
    [
        Vec3::ZERO,
        l.hip,
        l.knee,
        r.hip,
        r.knee,
        l.shoulder,
        l.elbow,
        l.wrist,
        r.shoulder,
        r.elbow,
        r.wrist,
    ]
}

/// Points that are redder on a raw carcass (joints, hock cuts, wing tips), rest pose.
pub fn red_spots() -> Vec<(Vec3, f32)> {
    let mut v = vec![(Vec3::new(0.13, 0.0, -0.004), 0.022)]; // neck cut
    for s in [1.0, -1.0] {
        let p = side(s);
        v.push((p.hock, 0.016));
        v.push((p.knee, 0.018));
        v.push((p.elbow, 0.014));
        v.push((p.wrist, 0.014));
        v.push((p.tip, 0.020));
    }
    v
}

/// The primitives with their bone: body parts on bone 0, limb segments on their joint.
fn prims() -> Vec<(Prim, usize)> {
    use Prim::*;
    let mut v = vec![
        (
            Ellipsoid(Vec3::new(0.0, 0.0, -0.002), Vec3::new(0.108, 0.070, 0.056)),
            0,
        ),
        (
            Ellipsoid(
                Vec3::new(0.030, 0.030, 0.018),
                Vec3::new(0.085, 0.043, 0.050),
            ),
            0,
        ),
        (
            Ellipsoid(
                Vec3::new(0.030, -0.030, 0.018),
                Vec3::new(0.085, 0.043, 0.050),
            ),
            0,
        ),
        (
            Ellipsoid(Vec3::new(0.040, 0.0, 0.046), Vec3::new(0.070, 0.010, 0.020)),
            0,
        ),
        (
            Cone(
                Vec3::new(0.085, 0.0, 0.0),
                Vec3::new(0.128, 0.0, -0.004),
                0.030,
                0.019,
            ),
            0,
        ),
        (
            Ellipsoid(
                Vec3::new(-0.112, 0.0, -0.010),
                Vec3::new(0.026, 0.030, 0.020),
            ),
            0,
        ),
    ];
    for (s, base) in [(1.0f32, 1usize), (-1.0, 3)] {
        let p = side(s);
        v.push((Cone(p.hip, p.knee, 0.038, 0.028), base));
        // Drumstick: the muscle swells below the knee, then tapers to the bare shank.
        let m1 = p.knee + (p.hock - p.knee) * 0.3;
        let m2 = p.knee + (p.hock - p.knee) * 0.88;
        v.push((Cone(p.knee, m1, 0.025, 0.028), base + 1));
        v.push((Cone(m1, m2, 0.028, 0.0095), base + 1));
        v.push((Ellipsoid(p.hock, Vec3::new(0.013, 0.012, 0.012)), base + 1));
    }
    for (s, base) in [(1.0f32, 5usize), (-1.0, 8)] {
        let p = side(s);
        v.push((Cone(p.shoulder, p.elbow, 0.021, 0.014), base));
        // The flat and the tip are flat: two parallel cones side by side in the wing plane.
        let flat =
            |a: Vec3, b: Vec3, half: f32| (b - a).cross(Vec3::Z).normalize_or(Vec3::X) * half;
        let o = flat(p.elbow, p.wrist, 0.006);
        v.push((Cone(p.elbow + o, p.wrist + o * 0.6, 0.012, 0.009), base + 1));
        v.push((Cone(p.elbow - o, p.wrist - o * 0.6, 0.012, 0.009), base + 1));
        let o = flat(p.wrist, p.tip, 0.005);
        v.push((Cone(p.wrist + o, p.tip, 0.009, 0.004), base + 2));
        v.push((Cone(p.wrist - o, p.tip, 0.009, 0.004), base + 2));
    }
    v
}

fn sd_ellipsoid(p: Vec3, r: Vec3) -> f32 {
    // Inigo Quilez' bound: exact on the axes, good enough for meshing and weights.
    let k0 = (p / r).length();
    let k1 = (p / (r * r)).length();
    if k1 < 1e-9 {
        -r.min_element()
    } else {
        k0 * (k0 - 1.0) / k1
    }
}

fn sd_round_cone(p: Vec3, a: Vec3, b: Vec3, r1: f32, r2: f32) -> f32 {
    let ba = b - a;
    let l2 = ba.length_squared();
    let rr = r1 - r2;
    let a2 = l2 - rr * rr;
    let il2 = 1.0 / l2;
    let pa = p - a;
    let y = pa.dot(ba);
    let z = y - l2;
    let x2 = (pa * l2 - ba * y).length_squared();
    let y2 = y * y * l2;
    let z2 = z * z * l2;
    let k = rr.signum() * rr * rr * x2;
    if z.signum() * a2 * z2 > k {
        return (x2 + z2).sqrt() * il2 - r2;
    }
    if y.signum() * a2 * y2 < k {
        return (x2 + y2).sqrt() * il2 - r1;
    }
    ((x2 * a2 * il2).sqrt() + y * rr) * il2 - r1
}

fn prim_sd(p: Vec3, prim: &Prim) -> f32 {
    match *prim {
        Prim::Ellipsoid(c, r) => sd_ellipsoid(p - c, r),
        Prim::Cone(a, b, ra, rb) => sd_round_cone(p, a, b, ra, rb),
    }
}

/// Polynomial smooth minimum (blend radius `k`).
fn smin(a: f32, b: f32, k: f32) -> f32 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}

/// Signed distance of the whole carcass plus the per-bone distances (for weights).
struct Sdf {
    prims: Vec<(Prim, usize)>,
}

impl Sdf {
    fn eval(&self, p: Vec3) -> f32 {
        let mut d = f32::INFINITY;
        for (prim, bone) in &self.prims {
            // Wider blends on the body give the plump, skin-covered look; limbs blend less
            // so wing segments stay distinct.
            let k = if *bone == 0 { 0.018 } else { 0.010 };
            let pd = prim_sd(p, prim);
            d = if d.is_infinite() { pd } else { smin(d, pd, k) };
        }
        // Flatten the back a little (the carcass rests on it breast-up).
        let back = -(p.z + 0.050);
        let d = smax(d, back, 0.012);
        // The body-cavity opening at the rear (vent removed in evisceration), between
        // the hocks, and the neck opening at the front: soft-edged hollows.
        let vent = (p - Vec3::new(-0.128, 0.0, 0.012)).length() - 0.02;
        let neck = (p - Vec3::new(0.142, 0.0, -0.004)).length() - 0.012;
        smax(smax(d, -vent, 0.008), -neck, 0.006)
    }

    fn bone_distances(&self, p: Vec3, out: &mut [f32; 11]) {
        out.fill(f32::INFINITY);
        for (prim, bone) in &self.prims {
            out[*bone] = out[*bone].min(prim_sd(p, prim));
        }
    }

    fn gradient(&self, p: Vec3) -> Vec3 {
        let e = 2.5e-4;
        let dx = self.eval(p + Vec3::X * e) - self.eval(p - Vec3::X * e);
        let dy = self.eval(p + Vec3::Y * e) - self.eval(p - Vec3::Y * e);
        let dz = self.eval(p + Vec3::Z * e) - self.eval(p - Vec3::Z * e);
        Vec3::new(dx, dy, dz).normalize_or_zero()
    }
}

fn smax(a: f32, b: f32, k: f32) -> f32 {
    -smin(-a, -b, k)
}

/// Builds the default carcass mesh (rest pose, skinned). Deterministic.
pub fn generate(cell: f32) -> Mesh {
    let sdf = Sdf { prims: prims() };
    let lo = Vec3::new(-0.16, -0.18, -0.08);
    let hi = Vec3::new(0.17, 0.18, 0.10);
    let (positions, indices) = surface_nets(&sdf, lo, hi, cell);
    // Pull vertices onto the surface (surface nets vertices sit inside their cell).
    let positions: Vec<Vec3> = positions
        .par_iter()
        .map(|&p| {
            let mut p = p;
            for _ in 0..2 {
                let g = sdf.gradient(p);
                p -= g * sdf.eval(p);
            }
            p
        })
        .collect();
    let normals: Vec<Vec3> = positions.par_iter().map(|&p| sdf.gradient(p)).collect();
    let (vertex_joints, vertex_weights): (Vec<[u16; 4]>, Vec<[f32; 4]>) =
        positions.par_iter().map(|&p| bone_weights(&sdf, p)).unzip();
    let pivots = joint_pivots();
    let joints = JOINT_NAMES
        .iter()
        .zip(JOINT_PARENTS)
        .zip(pivots)
        .map(|((name, parent), pivot)| Joint {
            name: name.to_string(),
            parent,
            pivot,
        })
        .collect();
    Mesh {
        positions,
        normals,
        indices,
        skin: Some(Skin {
            joints,
            vertex_joints,
            vertex_weights,
        }),
    }
}

/// Soft bone weights from the per-bone distances: a 5 mm falloff blends skin across each
/// joint; the four largest weights are kept and renormalised (glTF's JOINTS_0/WEIGHTS_0).
fn bone_weights(sdf: &Sdf, p: Vec3) -> ([u16; 4], [f32; 4]) {
    let mut d = [0.0f32; 11];
    sdf.bone_distances(p, &mut d);
    let dmin = d.iter().cloned().fold(f32::INFINITY, f32::min);
    let mut w: Vec<(usize, f32)> = d
        .iter()
        .enumerate()
        .map(|(i, &di)| (i, (-(di - dmin) / 0.005).exp()))
        .collect();
    w.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let sum: f32 = w[..4].iter().map(|x| x.1).sum();
    let mut j = [0u16; 4];
    let mut ww = [0f32; 4];
    for k in 0..4 {
        j[k] = w[k].0 as u16;
        ww[k] = w[k].1 / sum;
    }
    (j, ww)
}

/// Naive surface nets: one vertex per sign-changing cell (mean of its edge crossings),
/// one quad per sign-changing grid edge, oriented so normals point outwards.
fn surface_nets(sdf: &Sdf, lo: Vec3, hi: Vec3, cell: f32) -> (Vec<Vec3>, Vec<u32>) {
    let n = ((hi - lo) / cell).ceil().as_uvec3() + 1;
    let (nx, ny, nz) = (n.x as usize, n.y as usize, n.z as usize);
    let at = |i: usize, j: usize, k: usize| lo + Vec3::new(i as f32, j as f32, k as f32) * cell;
    let idx = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
    let field: Vec<f32> = (0..nx * ny * nz)
        .into_par_iter()
        .map(|f| {
            let i = f % nx;
            let j = (f / nx) % ny;
            let k = f / (nx * ny);
            sdf.eval(at(i, j, k))
        })
        .collect();
    const CORNERS: [[usize; 3]; 8] = [
        [0, 0, 0],
        [1, 0, 0],
        [0, 1, 0],
        [1, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [0, 1, 1],
        [1, 1, 1],
    ];
    const EDGES: [[usize; 2]; 12] = [
        [0, 1],
        [2, 3],
        [4, 5],
        [6, 7],
        [0, 2],
        [1, 3],
        [4, 6],
        [5, 7],
        [0, 4],
        [1, 5],
        [2, 6],
        [3, 7],
    ];
    let mut cell_vertex = vec![u32::MAX; nx * ny * nz];
    let mut positions = Vec::new();
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let mut v = [0f32; 8];
                let mut inside = 0;
                for (c, o) in CORNERS.iter().enumerate() {
                    v[c] = field[idx(i + o[0], j + o[1], k + o[2])];
                    if v[c] < 0.0 {
                        inside += 1;
                    }
                }
                if inside == 0 || inside == 8 {
                    continue;
                }
                let mut sum = Vec3::ZERO;
                let mut cnt = 0.0;
                for e in EDGES {
                    let (a, b) = (v[e[0]], v[e[1]]);
                    if (a < 0.0) != (b < 0.0) {
                        let t = a / (a - b);
                        let pa = Vec3::from(CORNERS[e[0]].map(|x| x as f32));
                        let pb = Vec3::from(CORNERS[e[1]].map(|x| x as f32));
                        sum += pa + (pb - pa) * t;
                        cnt += 1.0;
                    }
                }
                cell_vertex[idx(i, j, k)] = positions.len() as u32;
                positions.push(at(i, j, k) + sum / cnt * cell);
            }
        }
    }
    let mut indices = Vec::new();
    let mut quad = |a: u32, b: u32, c: u32, d: u32, flip: bool| {
        if flip {
            indices.extend_from_slice(&[a, c, b, a, d, c]);
        } else {
            indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    };
    for k in 1..nz - 1 {
        for j in 1..ny - 1 {
            for i in 1..nx - 1 {
                let f0 = field[idx(i, j, k)] < 0.0;
                // Edge along +x: cells sharing it vary in (j, k).
                if f0 != (field[idx(i + 1, j, k)] < 0.0) {
                    let c = [
                        cell_vertex[idx(i, j - 1, k - 1)],
                        cell_vertex[idx(i, j, k - 1)],
                        cell_vertex[idx(i, j, k)],
                        cell_vertex[idx(i, j - 1, k)],
                    ];
                    quad(c[0], c[1], c[2], c[3], !f0);
                }
                if f0 != (field[idx(i, j + 1, k)] < 0.0) {
                    let c = [
                        cell_vertex[idx(i - 1, j, k - 1)],
                        cell_vertex[idx(i - 1, j, k)],
                        cell_vertex[idx(i, j, k)],
                        cell_vertex[idx(i, j, k - 1)],
                    ];
                    quad(c[0], c[1], c[2], c[3], !f0);
                }
                if f0 != (field[idx(i, j, k + 1)] < 0.0) {
                    let c = [
                        cell_vertex[idx(i - 1, j - 1, k)],
                        cell_vertex[idx(i, j - 1, k)],
                        cell_vertex[idx(i, j, k)],
                        cell_vertex[idx(i - 1, j, k)],
                    ];
                    quad(c[0], c[1], c[2], c[3], !f0);
                }
            }
        }
    }
    (positions, indices)
}

/// Grid cell of the committed asset (metres).
pub const DEFAULT_CELL: f32 = 0.004;

/// Generates the default carcass and writes it as a skinned .glb.
pub fn write_default_asset(path: &std::path::Path) -> anyhow::Result<()> {
    let mesh = generate(DEFAULT_CELL);
    let bytes = super::glb::to_glb(&mesh)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, bytes).map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_mesh_is_closed_and_outward() {
        let m = generate(0.006);
        assert!(m.indices.len() / 3 > 1000);
        // Closed: every undirected edge is shared by exactly two triangles.
        let mut edges = std::collections::HashMap::new();
        for t in m.indices.chunks(3) {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let bad = edges.values().filter(|&&c| c != 2).count();
        assert!(bad * 1000 < edges.len(), "{bad} non-manifold edges");
        // Outward: signed volume is positive and close to a broiler's (~1.5-2.5 l).
        let vol: f32 = m
            .indices
            .chunks(3)
            .map(|t| {
                let (a, b, c) = (
                    m.positions[t[0] as usize],
                    m.positions[t[1] as usize],
                    m.positions[t[2] as usize],
                );
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        assert!(vol > 0.0012 && vol < 0.0035, "volume {vol} m^3");
        let w = &m.skin.as_ref().unwrap().vertex_weights;
        assert!(w.iter().all(|w| (w.iter().sum::<f32>() - 1.0).abs() < 1e-4));
    }

    #[test]
    fn default_asset_triangle_count_in_range() {
        let m = generate(DEFAULT_CELL);
        let t = m.indices.len() / 3;
        assert!((10_000..=40_000).contains(&t), "{t} triangles");
    }
}
