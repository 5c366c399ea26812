//! Procedural broiler carcass: a smooth-blended signed-distance body (back, breast lobes,
//! keel, neck stump, tail), thighs, drumsticks ending in hock knobs (feet removed) and
//! three-segment wings, meshed by surface nets on a 4 mm grid, with linear-blend bone
//! weights for hips, knees, shoulders, elbows and wrists.
//!
//! The proportions come from a [`Body`] parameter set: [`Body::BROILER`] is the committed
//! asset; the carcass randomisation group (`render::family`) generates other body
//! families (heavy broiler, spent hen, poussin, long/narrow, round/wide) from other sets,
//! each a different mesh with the same skeleton, so `skin.rs` poses them all.
//!
//! No permissively licensed carcass scan exists (`shared/notes/renderer.md`), so the asset
//! is generated here and written to `assets/carcass.glb` by `glb::write_default_asset`; the
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

/// Shape parameters of one body family. Every field is a factor on the broiler's
/// proportions (1 = [`Body::BROILER`]); the limbs keep their attachment to the trunk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Body {
    /// Trunk length (x): back, breast, keel, vent and neck positions.
    pub length: f32,
    /// Trunk width (y): also moves hips and shoulders outwards.
    pub width: f32,
    /// Trunk depth (z, back to breast).
    pub depth: f32,
    /// Breast prominence: the breast lobes' height and width.
    pub breast: f32,
    /// Keel ridge size (a spent hen's keel shows; a broiler's is buried in breast).
    pub keel: f32,
    /// Back height: where the flattened back sits (below 1 = flatter, shallower back).
    pub back: f32,
    /// Thigh girth.
    pub thigh: f32,
    /// Drumstick girth.
    pub drum: f32,
    /// Leg length (hip to knee to hock).
    pub leg: f32,
    /// Wing size (segment lengths and girth).
    pub wing: f32,
    /// Neck stump length and girth.
    pub neck: f32,
    /// Tail (parson's nose) size.
    pub tail: f32,
}

impl Body {
    /// The default broiler (the committed asset).
    pub const BROILER: Body = Body {
        length: 1.0,
        width: 1.0,
        depth: 1.0,
        breast: 1.0,
        keel: 1.0,
        back: 1.0,
        thigh: 1.0,
        drum: 1.0,
        leg: 1.0,
        wing: 1.0,
        neck: 1.0,
        tail: 1.0,
    };

    fn trunk(&self) -> Vec3 {
        Vec3::new(self.length, self.width, self.depth)
    }

    /// Largest growth factor over the broiler (sizes the meshing grid).
    fn growth(&self) -> f32 {
        [
            self.length,
            self.width,
            self.depth,
            self.leg,
            self.wing,
            self.neck,
            self.tail,
            self.breast,
            self.keel,
            self.thigh,
            self.drum,
        ]
        .into_iter()
        .fold(1.0, f32::max)
    }

    /// Every factor finite and within [0.5, 2] (a shape the SDF meshes cleanly).
    pub fn check(&self) -> anyhow::Result<()> {
        let f = [
            ("length", self.length),
            ("width", self.width),
            ("depth", self.depth),
            ("breast", self.breast),
            ("keel", self.keel),
            ("back", self.back),
            ("thigh", self.thigh),
            ("drum", self.drum),
            ("leg", self.leg),
            ("wing", self.wing),
            ("neck", self.neck),
            ("tail", self.tail),
        ];
        for (name, v) in f {
            anyhow::ensure!(
                v.is_finite() && (0.5..=2.0).contains(&v),
                "body factor {name} = {v} must be within [0.5, 2]"
            );
        }
        Ok(())
    }
}

impl Default for Body {
    fn default() -> Self {
        Body::BROILER
    }
}

/// `p0` moved with its anchor (`anchor0` → `anchor`) and its distance from the anchor
/// scaled by `k`. Written so that the broiler's points come out bit-identical.
fn limb(p0: Vec3, anchor0: Vec3, anchor: Vec3, k: f32) -> Vec3 {
    p0 + (anchor - anchor0) + (p0 - anchor0) * (k - 1.0)
}

fn side(b: &Body, s: f32) -> Side {
    let t = b.trunk();
    let hip0 = Vec3::new(-0.032, s * 0.048, -0.008);
    let knee0 = Vec3::new(0.004, s * 0.072, 0.032);
    let hock0 = Vec3::new(-0.112, s * 0.036, 0.056);
    let shoulder0 = Vec3::new(0.068, s * 0.058, 0.004);
    let elbow0 = Vec3::new(0.012, s * 0.098, -0.018);
    let wrist0 = Vec3::new(0.082, s * 0.104, -0.030);
    let tip0 = Vec3::new(0.030, s * 0.115, -0.045);
    let hip = hip0 * t;
    let knee = limb(knee0, hip0, hip, b.leg);
    let hock = limb(hock0, knee0, knee, b.leg);
    let shoulder = shoulder0 * t;
    let elbow = limb(elbow0, shoulder0, shoulder, b.wing);
    let wrist = limb(wrist0, elbow0, elbow, b.wing);
    let tip = limb(tip0, wrist0, wrist, b.wing);
    Side {
        hip,
        knee,
        hock,
        shoulder,
        elbow,
        wrist,
        tip,
    }
}

/// Joint pivots (rest pose) of the broiler, in joint order.
pub fn joint_pivots() -> [Vec3; 11] {
    joint_pivots_of(&Body::BROILER)
}

/// Joint pivots (rest pose) of body `b`, in joint order.
pub fn joint_pivots_of(b: &Body) -> [Vec3; 11] {
    let (l, r) = (side(b, 1.0), side(b, -1.0));
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

/// Where a wing ends (rest pose) on side `s` (+1 left, -1 right): the cut planes of
/// missing parts need the tip, which is no joint.
pub fn wing_tip(b: &Body, s: f32) -> Vec3 {
    side(b, s).tip
}

/// Where a leg ends (the hock, feet removed) on side `s`.
pub fn hock(b: &Body, s: f32) -> Vec3 {
    side(b, s).hock
}

/// Points that are redder on a raw carcass (joints, hock cuts, wing tips), rest pose.
pub fn red_spots() -> Vec<(Vec3, f32)> {
    red_spots_of(&Body::BROILER)
}

/// [`red_spots`] of body `b`.
pub fn red_spots_of(b: &Body) -> Vec<(Vec3, f32)> {
    // Neck cut.
    let neck = Vec3::new(0.13 * b.length + 0.043 * (b.neck - 1.0), 0.0, -0.004);
    let mut v = vec![(neck, 0.022)];
    for s in [1.0, -1.0] {
        let p = side(b, s);
        v.push((p.hock, 0.016));
        v.push((p.knee, 0.018));
        v.push((p.elbow, 0.014));
        v.push((p.wrist, 0.014));
        v.push((p.tip, 0.020));
    }
    v
}

/// The primitives of body `b` with their bone: body parts on bone 0, limb segments on
/// their joint. Every broiler value is a literal times a factor of 1 (bit-identical).
fn prims(b: &Body) -> Vec<(Prim, usize)> {
    use Prim::*;
    let t = b.trunk();
    let (l, w, d) = (b.length, b.width, b.depth);
    let lobe_r = Vec3::new(0.085 * l, 0.043 * w * b.breast.sqrt(), 0.050 * d * b.breast);
    let lobe_z = 0.018 * d * b.breast;
    let neck_end = Vec3::new(0.128 * l + 0.043 * (b.neck - 1.0), 0.0, -0.004);
    let neck_r = w * b.neck.sqrt();
    let mut v = vec![
        (
            Ellipsoid(
                Vec3::new(0.0, 0.0, -0.002) * t,
                Vec3::new(0.108, 0.070, 0.056) * t,
            ),
            0,
        ),
        (
            Ellipsoid(Vec3::new(0.030 * l, 0.030 * w, lobe_z), lobe_r),
            0,
        ),
        (
            Ellipsoid(Vec3::new(0.030 * l, -0.030 * w, lobe_z), lobe_r),
            0,
        ),
        (
            Ellipsoid(
                Vec3::new(0.040, 0.0, 0.046) * t,
                Vec3::new(0.070 * l, 0.010 * b.keel, 0.020 * d * b.keel),
            ),
            0,
        ),
        (
            Cone(
                Vec3::new(0.085 * l, 0.0, 0.0),
                neck_end,
                0.030 * neck_r,
                0.019 * neck_r,
            ),
            0,
        ),
        (
            Ellipsoid(
                Vec3::new(-0.112, 0.0, -0.010) * t,
                Vec3::new(0.026, 0.030, 0.020) * b.tail,
            ),
            0,
        ),
    ];
    for (s, base) in [(1.0f32, 1usize), (-1.0, 3)] {
        let p = side(b, s);
        v.push((Cone(p.hip, p.knee, 0.038 * b.thigh, 0.028 * b.thigh), base));
        // Drumstick: the muscle swells below the knee, then tapers to the bare shank.
        let m1 = p.knee + (p.hock - p.knee) * 0.3;
        let m2 = p.knee + (p.hock - p.knee) * 0.88;
        v.push((Cone(p.knee, m1, 0.025 * b.drum, 0.028 * b.drum), base + 1));
        v.push((Cone(m1, m2, 0.028 * b.drum, 0.0095 * b.drum), base + 1));
        v.push((
            Ellipsoid(p.hock, Vec3::new(0.013, 0.012, 0.012) * b.drum.sqrt()),
            base + 1,
        ));
    }
    let g = b.wing;
    for (s, base) in [(1.0f32, 5usize), (-1.0, 8)] {
        let p = side(b, s);
        v.push((Cone(p.shoulder, p.elbow, 0.021 * g, 0.014 * g), base));
        // The flat and the tip are flat: two parallel cones side by side in the wing plane.
        let flat =
            |a: Vec3, b: Vec3, half: f32| (b - a).cross(Vec3::Z).normalize_or(Vec3::X) * half;
        let o = flat(p.elbow, p.wrist, 0.006 * g);
        v.push((
            Cone(p.elbow + o, p.wrist + o * 0.6, 0.012 * g, 0.009 * g),
            base + 1,
        ));
        v.push((
            Cone(p.elbow - o, p.wrist - o * 0.6, 0.012 * g, 0.009 * g),
            base + 1,
        ));
        let o = flat(p.wrist, p.tip, 0.005 * g);
        v.push((Cone(p.wrist + o, p.tip, 0.009 * g, 0.004 * g), base + 2));
        v.push((Cone(p.wrist - o, p.tip, 0.009 * g, 0.004 * g), base + 2));
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
    /// Back plane height (z), vent centre and radius, neck-opening centre and radius.
    back_z: f32,
    vent: (Vec3, f32),
    neck: (Vec3, f32),
}

impl Sdf {
    fn new(b: &Body) -> Sdf {
        Sdf {
            prims: prims(b),
            back_z: 0.050 * b.depth * b.back,
            vent: (
                Vec3::new(-0.128 * b.length, 0.0, 0.012 * b.depth),
                0.02 * b.width,
            ),
            neck: (
                Vec3::new(0.142 * b.length + 0.043 * (b.neck - 1.0), 0.0, -0.004),
                0.012 * b.width * b.neck.sqrt(),
            ),
        }
    }
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
        let back = -(p.z + self.back_z);
        let d = smax(d, back, 0.012);
        // The body-cavity opening at the rear (vent removed in evisceration), between
        // the hocks, and the neck opening at the front: soft-edged hollows.
        let vent = (p - self.vent.0).length() - self.vent.1;
        let neck = (p - self.neck.0).length() - self.neck.1;
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
    generate_body(&Body::BROILER, cell)
}

/// Builds the carcass mesh of body `b` (rest pose, skinned, the same joints as the
/// broiler with pivots moved to `b`'s anatomy). Deterministic.
pub fn generate_body(b: &Body, cell: f32) -> Mesh {
    let sdf = Sdf::new(b);
    let g = b.growth();
    let lo = Vec3::new(-0.16, -0.18, -0.08) * g;
    let hi = Vec3::new(0.17, 0.18, 0.10) * g;
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
    let pivots = joint_pivots_of(b);
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

/// A grid cell's corners, as offsets from its lowest one (bit 0 = x, 1 = y, 2 = z).
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
/// The cell's 12 edges, as pairs of [`CORNERS`] indices.
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
