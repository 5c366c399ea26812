//! Reading and writing carcass meshes as binary glTF (.glb).
//!
//! Writing: the generator's skinned mesh becomes one skinned mesh node plus a joint
//! hierarchy (node names = joint names, inverse bind matrices = translate(-pivot)). The
//! JSON is built with serde_json and packed by hand: simpler to audit than gltf_json's
//! builder, and `gltf` itself validates it when read back.
//!
//! Reading goes through `gltf::import_slice`: every triangle primitive of every mesh
//! node in the default scene is baked into one mesh in the carcass frame; the first skin
//! found supplies joints (pivot = translation of the inverse of the inverse bind matrix).
//! Rigid meshes are fine. Errors (not panics) for malformed files, non-triangle
//! primitives, missing positions and absurd sizes.
//!
//! glTF is +Y up, +Z forward; the carcass frame is +Z up (breast), +X forward (neck):
//! carcass (x, y, z) = glTF (z, x, y), a cyclic permutation, i.e. a proper rotation.

use std::path::Path;

use glam::{Mat4, Vec3};
use serde_json::json;

use super::mesh::{Joint, Mesh, Skin};

/// Errors loading a carcass .glb.
#[derive(Debug, thiserror::Error)]
pub enum GlbError {
    #[error("cannot read carcass mesh {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("carcass mesh {0}: not a valid glTF/GLB file: {1}")]
    Parse(String, gltf::Error),
    #[error(
        "carcass mesh {0}: primitive {1} of mesh {2:?} is {3:?}, only triangles are supported"
    )]
    NotTriangles(String, usize, String, gltf::mesh::Mode),
    #[error("carcass mesh {0}: primitive {1} of mesh {2:?} has no POSITION attribute")]
    NoPositions(String, usize, String),
    #[error("carcass mesh {0}: {1}")]
    Invalid(String, String),
}

fn to_gltf(p: Vec3) -> [f32; 3] {
    [p.y, p.z, p.x]
}

fn from_gltf(p: [f32; 3]) -> Vec3 {
    Vec3::new(p[2], p[0], p[1])
}

/// glTF `componentType` and `bufferView.target` codes used here.
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const UNSIGNED_SHORT: u32 = 5123;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// The binary chunk being filled and the JSON `bufferViews` / `accessors` that describe
/// it: one view and one accessor per attribute, each view 4-byte aligned.
#[derive(Default)]
struct BinBuilder {
    bin: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl BinBuilder {
    /// Appends a buffer view + accessor; returns the accessor index.
    fn push(
        &mut self,
        bytes: Vec<u8>,
        ctype: u32,
        count: usize,
        ty: &str,
        target: Option<u32>,
        minmax: Option<([f32; 3], [f32; 3])>,
    ) -> usize {
        self.pad();
        let mut view =
            json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.bin.extend_from_slice(&bytes);
        self.views.push(view);
        let mut acc = json!({"bufferView": self.views.len() - 1, "componentType": ctype,
                             "count": count, "type": ty});
        if let Some((lo, hi)) = minmax {
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    /// Zero-pads the binary chunk to a multiple of 4 bytes (glTF alignment).
    fn pad(&mut self) {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
    }
}

/// Little-endian bytes of a run of f32s (glTF buffers are little-endian).
fn f32_bytes(xs: impl Iterator<Item = f32>, capacity: usize) -> Vec<u8> {
    let mut b = Vec::with_capacity(capacity);
    xs.for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    b
}

/// Per-axis min and max of the positions in glTF axes: the POSITION accessor must carry them.
fn gltf_bounds(positions: &[Vec3]) -> ([f32; 3], [f32; 3]) {
    positions.iter().fold(
        ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
        |(mut lo, mut hi), &p| {
            let g = to_gltf(p);
            for k in 0..3 {
                lo[k] = lo[k].min(g[k]);
                hi[k] = hi[k].max(g[k]);
            }
            (lo, hi)
        },
    )
}

/// Serialises a mesh (skinned or rigid) to .glb bytes.
pub fn to_glb(mesh: &Mesh) -> anyhow::Result<Vec<u8>> {
    let nv = mesh.positions.len();
    anyhow::ensure!(nv > 0 && mesh.indices.len() >= 3, "mesh is empty");
    let mut bb = BinBuilder::default();
    let (lo, hi) = gltf_bounds(&mesh.positions);
    let b = f32_bytes(mesh.positions.iter().flat_map(|&p| to_gltf(p)), nv * 12);
    let pos = bb.push(b, FLOAT, nv, "VEC3", Some(ARRAY_BUFFER), Some((lo, hi)));
    let b = f32_bytes(
        mesh.normals
            .iter()
            .flat_map(|&p| to_gltf(p.normalize_or(Vec3::Z))),
        nv * 12,
    );
    let nor = bb.push(b, FLOAT, nv, "VEC3", Some(ARRAY_BUFFER), None);
    let mut b = Vec::with_capacity(mesh.indices.len() * 4);
    mesh.indices
        .iter()
        .for_each(|&i| b.extend_from_slice(&i.to_le_bytes()));
    let idx = bb.push(
        b,
        UNSIGNED_INT,
        mesh.indices.len(),
        "SCALAR",
        Some(ELEMENT_ARRAY_BUFFER),
        None,
    );
    let mut attributes = json!({"POSITION": pos, "NORMAL": nor});
    let mut nodes = vec![json!({"name": "carcass", "mesh": 0})];
    let mut skins = Vec::new();
    if let Some(skin) = &mesh.skin {
        skins.push(push_skin(&mut bb, skin, nv, &mut attributes, &mut nodes));
    }
    bb.pad();
    let mut root = json!({
        "asset": {"version": "2.0", "generator": "chicktrain procedural carcass"},
        "scene": 0,
        "scenes": [{"nodes": scene_nodes(mesh)}],
        "nodes": nodes,
        "meshes": [{"name": "carcass", "primitives": [{"attributes": attributes,
                     "indices": idx, "mode": 4}]}],
        "buffers": [{"byteLength": bb.bin.len()}],
        "bufferViews": bb.views,
        "accessors": bb.accessors,
    });
    if !skins.is_empty() {
        root["skins"] = json!(skins);
    }
    pack_glb(&root, &bb.bin)
}

/// The skin's share of the file: JOINTS_0 / WEIGHTS_0 attributes (`nv` vertices), the
/// inverse bind matrices (translate(-pivot)), one node per joint after the mesh node;
/// returns the `skins[0]` JSON.
fn push_skin(
    bb: &mut BinBuilder,
    skin: &Skin,
    nv: usize,
    attributes: &mut serde_json::Value,
    nodes: &mut Vec<serde_json::Value>,
) -> serde_json::Value {
    let mut b = Vec::with_capacity(nv * 8);
    skin.vertex_joints.iter().for_each(|j| {
        j.iter()
            .for_each(|&x| b.extend_from_slice(&x.to_le_bytes()))
    });
    let jo = bb.push(b, UNSIGNED_SHORT, nv, "VEC4", Some(ARRAY_BUFFER), None);
    let b = f32_bytes(skin.vertex_weights.iter().flatten().copied(), nv * 16);
    let we = bb.push(b, FLOAT, nv, "VEC4", Some(ARRAY_BUFFER), None);
    attributes["JOINTS_0"] = json!(jo);
    attributes["WEIGHTS_0"] = json!(we);
    let b = f32_bytes(
        skin.joints
            .iter()
            .flat_map(|j| Mat4::from_translation(-Vec3::from(to_gltf(j.pivot))).to_cols_array()),
        0,
    );
    let ibm = bb.push(b, FLOAT, skin.joints.len(), "MAT4", None, None);
    let base = nodes.len();
    nodes.extend(joint_nodes(skin, base));
    nodes[0]["skin"] = json!(0);
    let joints: Vec<usize> = (0..skin.joints.len()).map(|k| base + k).collect();
    let root = skin
        .joints
        .iter()
        .position(|j| j.parent.is_none())
        .unwrap_or(0)
        + base;
    json!({"joints": joints, "inverseBindMatrices": ibm, "skeleton": root})
}

/// The joint hierarchy as glTF nodes (node `base + k` is joint `k`): name, translation
/// relative to the parent joint's pivot, children.
fn joint_nodes(skin: &Skin, base: usize) -> Vec<serde_json::Value> {
    let mut nodes = Vec::with_capacity(skin.joints.len());
    for (i, j) in skin.joints.iter().enumerate() {
        let parent_pivot = j.parent.map(|p| skin.joints[p].pivot).unwrap_or(Vec3::ZERO);
        let children: Vec<usize> = skin
            .joints
            .iter()
            .enumerate()
            .filter(|(_, c)| c.parent == Some(i))
            .map(|(k, _)| base + k)
            .collect();
        let mut node = json!({"name": j.name,
                              "translation": to_gltf(j.pivot - parent_pivot)});
        if !children.is_empty() {
            node["children"] = json!(children);
        }
        nodes.push(node);
    }
    nodes
}

/// The scene's root nodes: the mesh node, then every root joint.
fn scene_nodes(mesh: &Mesh) -> Vec<usize> {
    let mut scene_nodes = vec![0usize];
    if let Some(skin) = &mesh.skin {
        for (k, j) in skin.joints.iter().enumerate() {
            if j.parent.is_none() {
                scene_nodes.push(1 + k);
            }
        }
    }
    scene_nodes
}

/// The GLB container: 12-byte header, the JSON chunk (space-padded to 4 bytes), then the
/// binary chunk (already 4-byte aligned).
fn pack_glb(root: &serde_json::Value, bin: &[u8]) -> anyhow::Result<Vec<u8>> {
    let mut text = serde_json::to_vec(root)?;
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    Ok(out)
}

/// Loads a carcass mesh from a .glb/.gltf file.
pub fn load(path: &Path) -> Result<Mesh, GlbError> {
    let bytes = std::fs::read(path).map_err(|source| GlbError::Io {
        path: path.display().to_string(),
        source,
    })?;
    from_slice(&bytes, &path.display().to_string())
}

/// Parses .glb bytes; `name` is used in error messages.
pub fn from_slice(bytes: &[u8], name: &str) -> Result<Mesh, GlbError> {
    let name = name.to_string();
    let (doc, buffers, _) =
        gltf::import_slice(bytes).map_err(|e| GlbError::Parse(name.clone(), e))?;
    let invalid = |msg: String| GlbError::Invalid(name.clone(), msg);
    let mesh_nodes = scene_mesh_nodes(&doc).map_err(invalid)?;
    let skin_doc = mesh_nodes.iter().find_map(|(n, _)| n.skin());
    let mut baked = BakedMesh::new();
    for (node, world) in &mesh_nodes {
        let m = node.mesh().expect("filtered above");
        let mname = m.name().unwrap_or("").to_string();
        // Skinned meshes ignore their node transform (glTF spec); rigid ones use it.
        let skinned = node.skin().is_some() && skin_doc.is_some();
        let xf = if skinned { Mat4::IDENTITY } else { *world };
        for (pi, prim) in m.primitives().enumerate() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                return Err(GlbError::NotTriangles(name.clone(), pi, mname, prim.mode()));
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let pos: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| GlbError::NoPositions(name.clone(), pi, mname.clone()))?
                .collect();
            let at = PrimitiveAt { pi, mname: &mname };
            baked
                .add_primitive(&reader, &pos, xf, skinned, skin_doc.is_some(), at)
                .map_err(invalid)?;
        }
    }
    let BakedMesh {
        positions,
        mut normals,
        indices,
        vjoints,
        vweights,
        all_normals,
    } = baked;
    if indices.is_empty() {
        return Err(invalid("no triangles".into()));
    }
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(invalid("non-finite vertex positions".into()));
    }
    if !all_normals {
        normals = Mesh::compute_normals(&positions, &indices);
    }
    let skin = match skin_doc {
        None => None,
        Some(skin) => Some(read_skin(&skin, &buffers, vjoints, vweights).map_err(invalid)?),
    };
    let mesh = Mesh {
        positions,
        normals,
        indices,
        skin,
    };
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).max_element();
    if !(0.05..=2.0).contains(&size) {
        return Err(invalid(format!(
            "largest extent is {size:.3} m; carcass meshes must be in metres (0.05-2 m)"
        )));
    }
    Ok(mesh)
}

/// The mesh nodes of the default scene (else the first), with their world transforms,
/// in node-index order so the baked vertex order does not depend on the graph walk.
fn scene_mesh_nodes(doc: &gltf::Document) -> Result<Vec<(gltf::Node<'_>, Mat4)>, String> {
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| "no scene".to_string())?;
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut mesh_nodes = Vec::new();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if node.mesh().is_some() {
            mesh_nodes.push((node.clone(), world));
        }
        for c in node.children() {
            stack.push((c, world));
        }
    }
    mesh_nodes.sort_by_key(|(n, _)| n.index());
    if mesh_nodes.is_empty() {
        return Err("the default scene has no mesh".into());
    }
    Ok(mesh_nodes)
}

/// Where a primitive sits, for error messages: its index and its mesh's name.
struct PrimitiveAt<'a> {
    pi: usize,
    mname: &'a str,
}

/// Every primitive baked so far into one vertex/index list in the carcass frame, with
/// per-vertex joints and weights once the file has a skin.
struct BakedMesh {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    indices: Vec<u32>,
    vjoints: Vec<[u16; 4]>,
    vweights: Vec<[f32; 4]>,
    /// Every primitive had normals; otherwise they are recomputed for the whole mesh.
    all_normals: bool,
}

impl BakedMesh {
    /// Nothing baked yet; `all_normals` holds until a primitive lacks NORMAL.
    fn new() -> Self {
        BakedMesh {
            positions: Vec::new(),
            normals: Vec::new(),
            indices: Vec::new(),
            vjoints: Vec::new(),
            vweights: Vec::new(),
            all_normals: true,
        }
    }

    /// Appends one triangle primitive (`pos` already read) transformed by `xf`: normals,
    /// indices offset past the vertices so far, and, where the file has a skin, joints
    /// and normalised weights (rigid primitives get joint 0 at weight 1).
    fn add_primitive<'a, 's, F>(
        &mut self,
        reader: &gltf::mesh::Reader<'a, 's, F>,
        pos: &[[f32; 3]],
        xf: Mat4,
        skinned: bool,
        has_skin: bool,
        at: PrimitiveAt,
    ) -> Result<(), String>
    where
        F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        let PrimitiveAt { pi, mname } = at;
        let base = self.positions.len() as u32;
        let n = pos.len();
        self.positions.extend(
            pos.iter()
                .map(|p| from_gltf(xf.transform_point3(Vec3::from(*p)).into())),
        );
        match reader.read_normals() {
            Some(ns) => self.normals.extend(ns.map(|p| {
                from_gltf(
                    xf.transform_vector3(Vec3::from(p))
                        .normalize_or(Vec3::Y)
                        .into(),
                )
            })),
            None => {
                self.all_normals = false;
                self.normals.extend(std::iter::repeat_n(Vec3::Z, n));
            }
        }
        let idx: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if !idx.len().is_multiple_of(3) {
            return Err(format!(
                "primitive {pi} of mesh {mname:?} has {} indices, not a multiple of 3",
                idx.len()
            ));
        }
        if let Some(bad) = idx.iter().find(|&&i| i as usize >= n) {
            return Err(format!(
                "primitive {pi} of mesh {mname:?}: index {bad} out of range ({n} vertices)"
            ));
        }
        self.indices.extend(idx.iter().map(|i| i + base));
        if skinned {
            let (j, w) = read_joints_weights(reader, n, pi)?;
            self.vjoints.extend(j);
            self.vweights.extend(w);
        } else if has_skin {
            self.vjoints.extend(std::iter::repeat_n([0u16; 4], n));
            self.vweights
                .extend(std::iter::repeat_n([1.0f32, 0.0, 0.0, 0.0], n));
        }
        Ok(())
    }
}

/// JOINTS_0 and WEIGHTS_0 of a skinned primitive of `n` vertices (joint 0 at weight 1
/// where absent), weights normalised to sum 1 (all-zero weights become joint 0).
fn read_joints_weights<'a, 's, F>(
    reader: &gltf::mesh::Reader<'a, 's, F>,
    n: usize,
    pi: usize,
) -> Result<(Vec<[u16; 4]>, Vec<[f32; 4]>), String>
where
    F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let j: Vec<[u16; 4]> = reader
        .read_joints(0)
        .map(|j| j.into_u16().collect())
        .unwrap_or_else(|| vec![[0; 4]; n]);
    let w: Vec<[f32; 4]> = reader
        .read_weights(0)
        .map(|w| w.into_f32().collect())
        .unwrap_or_else(|| vec![[1.0, 0.0, 0.0, 0.0]; n]);
    if j.len() != n || w.len() != n {
        return Err(format!(
            "primitive {pi}: JOINTS_0/WEIGHTS_0 count differs from POSITION"
        ));
    }
    let w = w
        .into_iter()
        .map(|w| {
            let s: f32 = w.iter().sum();
            if s > 1e-6 {
                w.map(|x| x / s)
            } else {
                [1.0, 0.0, 0.0, 0.0]
            }
        })
        .collect();
    Ok((j, w))
}

/// The skin's joints: hierarchy from the joint nodes' children, pivot = translation of
/// the inverse of each inverse bind matrix; checks the vertices' joint indices.
fn read_skin(
    skin: &gltf::Skin,
    buffers: &[gltf::buffer::Data],
    vjoints: Vec<[u16; 4]>,
    vweights: Vec<[f32; 4]>,
) -> Result<Skin, String> {
    let reader = skin.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let joints: Vec<gltf::Node> = skin.joints().collect();
    let ibms: Vec<Mat4> = match reader.read_inverse_bind_matrices() {
        Some(m) => m.map(|m| Mat4::from_cols_array_2d(&m)).collect(),
        None => vec![Mat4::IDENTITY; joints.len()],
    };
    if ibms.len() != joints.len() {
        return Err("skin: inverse bind matrix count differs from joint count".into());
    }
    let node_to_joint: std::collections::HashMap<usize, usize> = joints
        .iter()
        .enumerate()
        .map(|(k, n)| (n.index(), k))
        .collect();
    let mut parent = vec![None; joints.len()];
    for (k, n) in joints.iter().enumerate() {
        for c in n.children() {
            if let Some(&ck) = node_to_joint.get(&c.index()) {
                parent[ck] = Some(k);
            }
        }
    }
    let out: Vec<Joint> = joints
        .iter()
        .enumerate()
        .map(|(k, n)| Joint {
            name: n.name().unwrap_or("").to_string(),
            parent: parent[k],
            pivot: from_gltf(ibms[k].inverse().w_axis.truncate().into()),
        })
        .collect();
    if out.iter().any(|j| !j.pivot.is_finite()) {
        return Err("skin: an inverse bind matrix is singular or non-finite".into());
    }
    if let Some(bad) = vjoints.iter().flatten().find(|&&j| j as usize >= out.len()) {
        return Err(format!(
            "skin: vertex joint index {bad} out of range ({} joints)",
            out.len()
        ));
    }
    Ok(Skin {
        joints: out,
        vertex_joints: vjoints,
        vertex_weights: vweights,
    })
}

/// The committed procedural carcass, embedded so rendering works from any directory.
pub static DEFAULT_CARCASS_GLB: &[u8] = include_bytes!("../../assets/carcass.glb");

/// Parses the embedded default carcass.
pub fn default_carcass() -> Result<Mesh, GlbError> {
    from_slice(DEFAULT_CARCASS_GLB, "<embedded assets/carcass.glb>")
}

/// Generates the default carcass and writes it as a skinned .glb.
pub fn write_default_asset(path: &std::path::Path) -> anyhow::Result<()> {
    let mesh = super::carcass::generate(super::carcass::DEFAULT_CELL);
    let bytes = to_glb(&mesh)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, bytes).map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra(skinned: bool) -> Mesh {
        let positions = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.2, 0.0, 0.0),
            Vec3::new(0.0, 0.2, 0.0),
            Vec3::new(0.0, 0.0, 0.2),
        ];
        let indices = vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];
        let normals = Mesh::compute_normals(&positions, &indices);
        let skin = skinned.then(|| Skin {
            joints: vec![
                Joint {
                    name: "body".into(),
                    parent: None,
                    pivot: Vec3::ZERO,
                },
                Joint {
                    name: "hip_L".into(),
                    parent: Some(0),
                    pivot: Vec3::new(0.1, 0.05, 0.0),
                },
            ],
            vertex_joints: vec![[0, 1, 0, 0]; 4],
            vertex_weights: vec![[0.75, 0.25, 0.0, 0.0]; 4],
        });
        Mesh {
            positions,
            normals,
            indices,
            skin,
        }
    }

    #[test]
    fn roundtrip_skinned_and_rigid() {
        for skinned in [true, false] {
            let m = tetra(skinned);
            let back = from_slice(&to_glb(&m).unwrap(), "t").unwrap();
            assert_eq!(back.indices, m.indices);
            for (a, b) in back.positions.iter().zip(&m.positions) {
                assert!((*a - *b).length() < 1e-6);
            }
            match (&back.skin, &m.skin) {
                (Some(a), Some(b)) => {
                    assert_eq!(a.vertex_joints, b.vertex_joints);
                    assert_eq!(a.joints.len(), 2);
                    assert_eq!(a.joints[1].parent, Some(0));
                    assert!((a.joints[1].pivot - b.joints[1].pivot).length() < 1e-6);
                }
                (None, None) => {}
                _ => panic!("skin lost or invented"),
            }
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(matches!(
            from_slice(b"not a glb", "x"),
            Err(GlbError::Parse(..))
        ));
        let good = to_glb(&tetra(false)).unwrap();
        assert!(from_slice(&good[..good.len() / 2], "x").is_err());
        assert!(matches!(
            load(Path::new("/nonexistent/c.glb")),
            Err(GlbError::Io { .. })
        ));
        // Same file with the primitive switched to LINES (mode 1).
        let mut lines = good.clone();
        let at = lines.windows(8).position(|w| w == b"\"mode\":4").unwrap();
        lines[at + 7] = b'1';
        let e = from_slice(&lines, "lines.glb").unwrap_err();
        assert!(matches!(e, GlbError::NotTriangles(..)), "{e}");
        assert!(e.to_string().contains("only triangles"));
    }

    #[test]
    fn committed_asset_matches_the_generator() {
        // If this fails, run `cargo run --release --example gen_carcass` and commit.
        let fresh = to_glb(&super::super::carcass::generate(
            super::super::carcass::DEFAULT_CELL,
        ))
        .unwrap();
        assert!(fresh == DEFAULT_CARCASS_GLB, "assets/carcass.glb is stale");
    }

    #[test]
    fn embedded_default_loads_skinned() {
        let m = default_carcass().unwrap();
        let s = m.skin.as_ref().unwrap();
        assert_eq!(s.joints.len(), 11);
        assert!(s.joints.iter().any(|j| j.name == "wrist_R"));
        assert!((10_000..=40_000).contains(&m.triangle_count()));
    }
}
