//! The carcass asset a scene instances: its mesh and per-vertex redness ([`Asset`]), and
//! the one-per-process load of the embedded or a user's `.glb` ([`asset`]). Its own file
//! so that the scene sampler, the body families and the variety draws all stand on it
//! without importing each other.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use glam::Vec3;

use super::carcass;
use super::mesh::Mesh;

/// A carcass mesh ready to instance: the mesh and its per-vertex redness.
#[derive(Clone)]
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
        Asset::with_spots(mesh, &spots)
    }

    /// An asset whose redness comes from `spots` (rest-space centre, radius).
    pub fn with_spots(mesh: Mesh, spots: &[(Vec3, f32)]) -> Asset {
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
