//! Which wings and legs a carcass has and how they lie (carcass randomisation group):
//! wings folded / natural / spread, or cut at the wrist, the elbow or the shoulder; legs
//! bent / natural / straight, or cut at the knee (drumstick gone) or the hip (whole leg
//! gone). A missing part is removed from the mesh and its hole capped with a flat cut
//! surface (meat, bone at the centre), so the silhouette and the mask really change;
//! hiding it by colour would teach the model nothing.
//!
//! Cuts work on any skinned mesh with the generator's joint names
//! (`carcass::JOINT_NAMES`): the plane of a cut goes through the joint, facing along the
//! part (from the joint to the centroid of the part's vertices).

use std::collections::HashMap;

use glam::Vec3;
use rand::Rng;

use super::material::{CUT_BONE, CUT_MEAT};
use super::mesh::{Mesh, Skin};
use super::skin::Pose;

/// How one wing is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wing {
    Folded,
    Natural,
    Spread,
    /// Cut at the wrist (tip gone).
    NoTip,
    /// Cut at the elbow (flat and tip gone).
    Half,
    /// Cut at the shoulder.
    Missing,
}

/// How one leg is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Leg {
    Bent,
    Natural,
    Straight,
    /// Cut at the knee: the thigh stays.
    NoDrumstick,
    /// Cut at the hip.
    Missing,
}

/// The parts plan of one carcass (index 0 = left).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Parts {
    pub wings: [Wing; 2],
    pub legs: [Leg; 2],
}

/// Probabilities per side (the rest of each side's draw is a pose state): wing cut at
/// the wrist 5 %, at the elbow 3 %, at the shoulder 3 %; folded 42 %, natural 28 %,
/// spread 19 %. Leg cut at the knee 3 %, at the hip 2 %; bent 36 %, natural 39 %,
/// straight 20 %. The second side repeats the first's pose state 60 % of the time.
/// About 28 % of carcasses miss some part: damaged birds are common on a line, but
/// whole ones are the rule.
const WINGS: [(Wing, f64); 6] = [
    (Wing::Folded, 0.42),
    (Wing::Natural, 0.28),
    (Wing::Spread, 0.19),
    (Wing::NoTip, 0.05),
    (Wing::Half, 0.03),
    (Wing::Missing, 0.03),
];
const LEGS: [(Leg, f64); 5] = [
    (Leg::Bent, 0.36),
    (Leg::Natural, 0.39),
    (Leg::Straight, 0.20),
    (Leg::NoDrumstick, 0.03),
    (Leg::Missing, 0.02),
];

fn pick<T: Copy, R: Rng>(rng: &mut R, table: &[(T, f64)]) -> T {
    let u: f64 = rng.random_range(0.0..1.0);
    let mut acc = 0.0;
    for &(t, p) in table {
        acc += p;
        if u < acc {
            return t;
        }
    }
    table[table.len() - 1].0
}

/// The joint a cut goes through, the bones it removes, how far past the joint (m) the
/// plane lies, and whether a bone shows in the cut.
struct CutSpec {
    joint: &'static str,
    bones: &'static [&'static str],
    offset: f32,
    bone: bool,
}

impl Parts {
    /// Draws both sides (see the probability table above).
    pub fn sample<R: Rng>(rng: &mut R) -> Parts {
        let w0 = pick(rng, &WINGS);
        let w1 = pick(rng, &WINGS);
        let mirror_w = rng.random_bool(0.6);
        let l0 = pick(rng, &LEGS);
        let l1 = pick(rng, &LEGS);
        let mirror_l = rng.random_bool(0.6);
        // Cuts stay independent per side; only pose states are mirrored.
        let is_pose_w = |w: Wing| matches!(w, Wing::Folded | Wing::Natural | Wing::Spread);
        let is_pose_l = |l: Leg| matches!(l, Leg::Bent | Leg::Natural | Leg::Straight);
        let w1 = if mirror_w && is_pose_w(w0) && is_pose_w(w1) {
            w0
        } else {
            w1
        };
        let l1 = if mirror_l && is_pose_l(l0) && is_pose_l(l1) {
            l0
        } else {
            l1
        };
        Parts {
            wings: [w0, w1],
            legs: [l0, l1],
        }
    }

    /// All parts present, natural pose.
    pub fn whole() -> Parts {
        Parts {
            wings: [Wing::Natural; 2],
            legs: [Leg::Natural; 2],
        }
    }

    /// Sets the pose angles of each side from its state (radians; + spread = away from
    /// the body, + open = unfolded, + knee bend = drumstick towards the thigh):
    /// folded: spread −0.35…−0.1, open −0.45…−0.2; natural: spread −0.1…0.3, open
    /// −0.2…0.25; spread: spread 0.45…0.85, open 0.25…0.6. Bent: knee 0.3…0.6, lift
    /// 0…0.3; natural: knee −0.1…0.3; straight: knee −0.4…−0.15, lift −0.3…−0.05.
    /// The scaled-away wing tip of the base look is replaced by a real cut.
    pub fn pose<R: Rng>(&self, rng: &mut R, pose: &mut Pose) {
        for side in 0..2 {
            let (spread, open) = match self.wings[side] {
                Wing::Folded => ([-0.35, -0.1], [-0.45, -0.2]),
                Wing::Spread => ([0.45, 0.85], [0.25, 0.6]),
                _ => ([-0.1, 0.3], [-0.2, 0.25]),
            };
            pose.wing_spread[side] = rng.random_range(spread[0]..spread[1]);
            pose.wing_open[side] = rng.random_range(open[0]..open[1]);
            pose.missing_tip[side] = false;
            let (knee, lift) = match self.legs[side] {
                Leg::Bent => ([0.3, 0.6], [0.0, 0.3]),
                Leg::Straight => ([-0.4, -0.15], [-0.3, -0.05]),
                _ => ([-0.1, 0.3], [-0.2, 0.2]),
            };
            pose.knee_bend[side] = rng.random_range(knee[0]..knee[1]);
            pose.leg_lift[side] = rng.random_range(lift[0]..lift[1]);
        }
    }

    fn cuts(&self) -> Vec<(CutSpec, &'static str)> {
        let mut v = Vec::new();
        for (side, sfx) in [(0usize, "_L"), (1, "_R")] {
            let spec = match self.wings[side] {
                Wing::NoTip => Some(CutSpec {
                    joint: "wrist",
                    bones: &["wrist"],
                    offset: 0.002,
                    bone: false,
                }),
                Wing::Half => Some(CutSpec {
                    joint: "elbow",
                    bones: &["elbow", "wrist"],
                    offset: 0.003,
                    bone: true,
                }),
                Wing::Missing => Some(CutSpec {
                    joint: "shoulder",
                    bones: &["shoulder", "elbow", "wrist"],
                    offset: 0.006,
                    bone: true,
                }),
                _ => None,
            };
            v.extend(spec.map(|s| (s, sfx)));
            let spec = match self.legs[side] {
                Leg::NoDrumstick => Some(CutSpec {
                    joint: "knee",
                    bones: &["knee"],
                    offset: 0.004,
                    bone: true,
                }),
                Leg::Missing => Some(CutSpec {
                    joint: "hip",
                    bones: &["hip", "knee"],
                    offset: 0.016,
                    bone: false,
                }),
                _ => None,
            };
            v.extend(spec.map(|s| (s, sfx)));
        }
        v
    }

    /// True when some part is cut off.
    pub fn has_cuts(&self) -> bool {
        !self.cuts().is_empty()
    }

    /// The mesh (and its per-vertex redness) with the missing parts removed and capped.
    /// Meshes without the generator's skin, or with nothing missing, come back unchanged.
    pub fn apply(&self, mesh: &Mesh, redness: &[f32]) -> (Mesh, Vec<f32>) {
        let Some(skin) = &mesh.skin else {
            return (mesh.clone(), redness.to_vec());
        };
        let joint = |name: &str| skin.joints.iter().position(|j| j.name == name);
        let mut planes = Vec::new();
        for (spec, sfx) in self.cuts() {
            let Some(j) = joint(&format!("{}{sfx}", spec.joint)) else {
                continue;
            };
            let bones: Vec<u16> = spec
                .bones
                .iter()
                .filter_map(|b| joint(&format!("{b}{sfx}")).map(|i| i as u16))
                .collect();
            if let Some(p) = Plane::new(mesh, skin, j, &bones, spec.offset, spec.bone) {
                planes.push(p);
            }
        }
        if planes.is_empty() {
            return (mesh.clone(), redness.to_vec());
        }
        cut_and_cap(mesh, skin, redness, &planes)
    }
}

/// One cut: the plane (through `point`, `normal` towards the removed part) and the bones
/// whose vertices beyond it go.
struct Plane {
    point: Vec3,
    normal: Vec3,
    bones: Vec<u16>,
    bone: bool,
}

impl Plane {
    fn new(
        mesh: &Mesh,
        skin: &Skin,
        joint: usize,
        bones: &[u16],
        offset: f32,
        bone: bool,
    ) -> Option<Plane> {
        let pivot = skin.joints[joint].pivot;
        let (mut sum, mut n) = (Vec3::ZERO, 0usize);
        for (i, j) in skin.vertex_joints.iter().enumerate() {
            if bones.contains(&j[0]) {
                sum += mesh.positions[i];
                n += 1;
            }
        }
        if n == 0 {
            return None;
        }
        let normal = (sum / n as f32 - pivot).try_normalize()?;
        Some(Plane {
            point: pivot + normal * offset,
            normal,
            bones: bones.to_vec(),
            bone,
        })
    }

    fn removes(&self, p: Vec3, dominant: u16) -> bool {
        self.bones.contains(&dominant) && (p - self.point).dot(self.normal) > 0.0
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

/// Per vertex: whether a cut plane removes it (judged on its dominant bone).
fn beyond_planes(mesh: &Mesh, skin: &Skin, planes: &[Plane]) -> Vec<bool> {
    (0..mesh.positions.len())
        .map(|i| {
            let dom = skin.vertex_joints[i][0];
            planes.iter().any(|pl| pl.removes(mesh.positions[i], dom))
        })
        .collect()
}

/// Keeps the triangles of the largest connected piece of `kept` (`nv` vertices; the
/// lowest root on a tie), so nothing floats after a cut.
fn keep_largest_piece(kept: &mut Vec<[u32; 3]>, nv: usize) {
    let mut parent: Vec<u32> = (0..nv as u32).collect();
    for t in kept.iter() {
        union(&mut parent, t[0], t[1]);
        union(&mut parent, t[1], t[2]);
    }
    let mut size: HashMap<u32, usize> = HashMap::new();
    for t in kept.iter() {
        *size.entry(find(&mut parent, t[0])).or_default() += 1;
    }
    let main = size
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(r, _)| *r);
    kept.retain(|t| Some(find(&mut parent, t[0])) == main);
}

/// The holes the cuts opened: the rim (directed edges of `kept` triangles whose twin was in
/// a removed triangle), grouped by shared vertices, as (group root, its rim edges).
fn holes(
    kept: &[[u32; 3]],
    removed_edges: &HashMap<(u32, u32), ()>,
    nv: usize,
) -> Vec<(u32, Vec<(u32, u32)>)> {
    // Rim: directed edges of kept triangles whose twin was in a removed triangle.
    let mut have: HashMap<(u32, u32), ()> = HashMap::new();
    for t in kept {
        for e in 0..3 {
            have.insert((t[e], t[(e + 1) % 3]), ());
        }
    }
    let mut rim: Vec<(u32, u32)> = Vec::new();
    for t in kept {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if removed_edges.contains_key(&(b, a)) && !have.contains_key(&(b, a)) {
                rim.push((a, b));
            }
        }
    }
    rim.sort_unstable();
    // Holes: rim edges grouped by shared vertices.
    let mut hp: Vec<u32> = (0..nv as u32).collect();
    for &(a, b) in &rim {
        union(&mut hp, a, b);
    }
    let mut holes: Vec<(u32, Vec<(u32, u32)>)> = Vec::new();
    for &(a, b) in &rim {
        let r = find(&mut hp, a);
        match holes.iter_mut().find(|h| h.0 == r) {
            Some(h) => h.1.push((a, b)),
            None => holes.push((r, vec![(a, b)])),
        }
    }
    holes
}

/// Removes every triangle touching a vertex beyond a plane (on its bones), keeps the
/// largest connected piece (nothing floats), then closes each hole the cuts opened with
/// a fan of flat triangles from the hole's centre, its rim vertices moved onto the plane.
/// Cap vertices are separate from the skin's (flat normal, cut tissue code).
fn cut_and_cap(mesh: &Mesh, skin: &Skin, redness: &[f32], planes: &[Plane]) -> (Mesh, Vec<f32>) {
    let nv = mesh.positions.len();
    let gone = beyond_planes(mesh, skin, planes);
    let mut kept: Vec<[u32; 3]> = Vec::new();
    let mut removed_edges: HashMap<(u32, u32), ()> = HashMap::new();
    for t in mesh.indices.chunks_exact(3) {
        let t = [t[0], t[1], t[2]];
        if t.iter().any(|&v| gone[v as usize]) {
            for e in 0..3 {
                removed_edges.insert((t[e], t[(e + 1) % 3]), ());
            }
        } else {
            kept.push(t);
        }
    }
    keep_largest_piece(&mut kept, nv);
    let holes = holes(&kept, &removed_edges, nv);
    let mut positions = mesh.positions.clone();
    let mut normals = mesh.normals.clone();
    let mut red = redness.to_vec();
    let mut joints = skin.vertex_joints.clone();
    let mut weights = skin.vertex_weights.clone();
    let mut tris = kept;
    for (_, edges) in holes.iter().filter(|h| h.1.len() >= 3) {
        let mut verts: Vec<u32> = edges.iter().flat_map(|e| [e.0, e.1]).collect();
        verts.sort_unstable();
        verts.dedup();
        let c0 = verts.iter().map(|&v| positions[v as usize]).sum::<Vec3>() / verts.len() as f32;
        let pl = planes
            .iter()
            .min_by(|a, b| {
                let da = (c0 - a.point).dot(a.normal).abs();
                let db = (c0 - b.point).dot(b.normal).abs();
                da.total_cmp(&db)
            })
            .expect("planes is not empty");
        let mut cap: HashMap<u32, u32> = HashMap::new();
        for &v in &verts {
            let p = positions[v as usize];
            let d = (p - pl.point).dot(pl.normal);
            // Rim vertices lie within about a grid cell of the plane: flatten the cut.
            if d.abs() < 0.008 {
                positions[v as usize] = p - pl.normal * d;
            }
            cap.insert(v, positions.len() as u32);
            positions.push(positions[v as usize]);
            normals.push(pl.normal);
            red.push(CUT_MEAT);
            joints.push(joints[v as usize]);
            weights.push(weights[v as usize]);
        }
        let centre =
            verts.iter().map(|&v| positions[v as usize]).sum::<Vec3>() / verts.len() as f32;
        let nearest = *verts
            .iter()
            .min_by(|&&a, &&b| {
                (positions[a as usize] - centre)
                    .length_squared()
                    .total_cmp(&(positions[b as usize] - centre).length_squared())
            })
            .expect("a hole has vertices");
        let c = positions.len() as u32;
        positions.push(centre);
        normals.push(pl.normal);
        red.push(if pl.bone { CUT_BONE } else { CUT_MEAT });
        joints.push(joints[nearest as usize]);
        weights.push(weights[nearest as usize]);
        for &(a, b) in edges {
            tris.push([cap[&b], cap[&a], c]);
        }
    }
    // Compact: drop vertices no triangle uses.
    let mut remap = vec![u32::MAX; positions.len()];
    let mut out = Mesh {
        positions: Vec::new(),
        normals: Vec::new(),
        indices: Vec::with_capacity(tris.len() * 3),
        skin: Some(Skin {
            joints: skin.joints.clone(),
            vertex_joints: Vec::new(),
            vertex_weights: Vec::new(),
        }),
    };
    let mut out_red = Vec::new();
    let out_skin = out.skin.as_mut().expect("set above");
    for t in &tris {
        for &v in t {
            let v = v as usize;
            if remap[v] == u32::MAX {
                remap[v] = out.positions.len() as u32;
                out.positions.push(positions[v]);
                out.normals.push(normals[v]);
                out_red.push(red[v]);
                out_skin.vertex_joints.push(joints[v]);
                out_skin.vertex_weights.push(weights[v]);
            }
            out.indices.push(remap[v]);
        }
    }
    (out, out_red)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::carcass;

    /// Edges not shared by exactly two triangles, vertices welded by position (a cap's
    /// vertices duplicate its rim's, for their flat normals).
    fn closedness(m: &Mesh) -> usize {
        let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
        let id: Vec<u32> = m
            .positions
            .iter()
            .map(|p| {
                let n = weld.len() as u32;
                *weld.entry(p.to_array().map(f32::to_bits)).or_insert(n)
            })
            .collect();
        let mut edges = HashMap::new();
        for t in m.indices.chunks(3) {
            for e in 0..3 {
                let (a, b) = (id[t[e] as usize], id[t[(e + 1) % 3] as usize]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        edges.values().filter(|&&c| c != 2).count()
    }

    #[test]
    fn missing_parts_remove_geometry_and_are_capped() {
        let mesh = carcass::generate(0.006);
        let red = vec![0.0; mesh.positions.len()];
        let (same, _) = Parts::whole().apply(&mesh, &red);
        assert_eq!(same, mesh);
        let bad0 = closedness(&mesh);
        let v0 = mesh.volume();
        let skin = mesh.skin.as_ref().unwrap();
        let max_y = |m: &Mesh| m.positions.iter().map(|p| p.y).fold(f32::MIN, f32::max);
        for (parts, what) in [
            (
                Parts {
                    wings: [Wing::Missing, Wing::Natural],
                    legs: [Leg::Natural; 2],
                },
                "left wing",
            ),
            (
                Parts {
                    wings: [Wing::Half, Wing::NoTip],
                    legs: [Leg::NoDrumstick, Leg::Missing],
                },
                "mixed",
            ),
        ] {
            let (m, r) = parts.apply(&mesh, &red);
            assert_eq!(r.len(), m.positions.len());
            assert!(m.indices.iter().all(|&i| (i as usize) < m.positions.len()));
            assert!(m.normals.iter().all(|n| n.is_finite()));
            assert!(m.triangle_count() < mesh.triangle_count(), "{what}");
            // Still closed (caps fill the holes) and smaller.
            assert!(
                closedness(&m) <= bad0 + 4,
                "{what}: {} open edges",
                closedness(&m)
            );
            let v = m.volume();
            assert!(v < v0 * 0.995 && v > v0 * 0.6, "{what}: volume {v} vs {v0}");
            // Cut surfaces exist and carry the cut tissue code.
            assert!(r.iter().any(|&x| x >= CUT_MEAT), "{what}");
            let w = &m.skin.as_ref().unwrap().vertex_weights;
            assert!(w.iter().all(|w| (w.iter().sum::<f32>() - 1.0).abs() < 1e-4));
        }
        // The left wing is the mesh's +y extreme: without it, +y shrinks.
        let (m, _) = Parts {
            wings: [Wing::Missing, Wing::Natural],
            legs: [Leg::Natural; 2],
        }
        .apply(&mesh, &red);
        assert!(
            max_y(&m) < max_y(&mesh) - 0.015,
            "{} vs {}",
            max_y(&m),
            max_y(&mesh)
        );
        // No vertex dominated by the left elbow or wrist survives.
        let bone = |n: &str| skin.joints.iter().position(|j| j.name == n).unwrap() as u16;
        let (elbow_l, wrist_l) = (bone("elbow_L"), bone("wrist_L"));
        let s = m.skin.as_ref().unwrap();
        assert!(s
            .vertex_joints
            .iter()
            .all(|j| j[0] != wrist_l && j[0] != elbow_l));
        assert!(mesh
            .skin
            .as_ref()
            .unwrap()
            .vertex_joints
            .iter()
            .any(|j| j[0] == wrist_l));
    }

    #[test]
    fn sampled_parts_are_deterministic_and_mostly_whole() {
        use rand::SeedableRng;
        let mut a = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut b = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let pa: Vec<Parts> = (0..400).map(|_| Parts::sample(&mut a)).collect();
        let pb: Vec<Parts> = (0..400).map(|_| Parts::sample(&mut b)).collect();
        assert_eq!(pa, pb);
        let cut = pa.iter().filter(|p| p.has_cuts()).count();
        // Per carcass: 1 - (0.89 * 0.95)^2 ≈ 28.5 % have some part cut (114 of 400).
        assert!((80..=150).contains(&cut), "{cut}/400 with cuts");
        assert!(pa.iter().any(|p| p.wings[0] == Wing::Spread));
        assert!(pa.iter().any(|p| p.legs[1] == Leg::Missing));
    }
}
