//! The in-memory triangle mesh the renderer poses and traces: rest-pose positions and
//! normals, triangle indices and optional linear-blend skin (joints with pivots, four
//! joint indices and weights per vertex). Shared by the generator, the .glb codec and
//! the skinning code; holds no rendering state.

use glam::Vec3;

/// A joint of the skin. `pivot` is the joint's rest position in mesh space.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    pub name: String,
    pub parent: Option<usize>,
    pub pivot: Vec3,
}

/// Linear-blend skin: per vertex up to four joints and weights summing to 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Skin {
    pub joints: Vec<Joint>,
    pub vertex_joints: Vec<[u16; 4]>,
    pub vertex_weights: Vec<[f32; 4]>,
}

/// A rest-pose triangle mesh in the carcass frame (metres, +z out of the breast).
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub indices: Vec<u32>,
    pub skin: Option<Skin>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds of the rest pose.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    }

    /// The enclosed volume (m³) of a closed mesh with outward-wound triangles: the sum of
    /// the signed tetrahedra each triangle spans with the origin.
    pub fn volume(&self) -> f32 {
        self.indices
            .chunks(3)
            .map(|t| {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| self.positions[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Smooth vertex normals from the triangles (area weighted).
    pub fn compute_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
        let mut n = vec![Vec3::ZERO; positions.len()];
        for t in indices.chunks_exact(3) {
            let (a, b, c) = (t[0] as usize, t[1] as usize, t[2] as usize);
            let f = (positions[b] - positions[a]).cross(positions[c] - positions[a]);
            n[a] += f;
            n[b] += f;
            n[c] += f;
        }
        n.iter().map(|v| v.normalize_or(Vec3::Z)).collect()
    }
}
