//! A distractor's kind and appearance, and the instance numbers that mark its triangles:
//! what the tracer and the label step need to know about props, apart from how
//! `distractor` builds them (so the tracer does not import the prop generator).

use glam::Vec3;

use super::noise::fbm3;
use super::surface::Surface;

/// First triangle instance number of distractors (carcasses are 0..64).
pub const PROP_BASE: u16 = 0x8000;

/// True for an id-buffer value (instance + 1) that belongs to a distractor.
#[inline]
pub fn is_prop_id(id: u16) -> bool {
    id > PROP_BASE
}

/// The kinds of distractor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PropKind {
    Glove,
    Hand,
    Shackle,
    Knife,
    Scraper,
    Packaging,
    FatScrap,
}

/// A distractor's appearance: constant material with a little low-frequency variation.
#[derive(Clone, Debug, PartialEq)]
pub struct PropMaterial {
    pub kind: PropKind,
    pub albedo: Vec3,
    pub f0: f32,
    pub roughness: f32,
    /// Metal-like look (high f0, little diffuse); kept below 0.5 so the tracer gives it
    /// the room's specular (only the plate traces reflection rays).
    pub metallic: f32,
    pub wrap: f32,
    pub sss_tint: Vec3,
    /// Amplitude of the colour variation.
    pub texture: f32,
    pub seed: u64,
}

impl PropMaterial {
    /// Surface at world point `p` (props are rigid: world = texture space).
    pub fn surface(&self, p: Vec3, n: Vec3) -> Surface {
        let v = fbm3(self.seed, p * 35.0, 2);
        Surface {
            albedo: self.albedo * (1.0 - 0.5 * self.texture + self.texture * v),
            normal: n,
            f0: Vec3::splat(self.f0),
            roughness: self.roughness,
            metallic: self.metallic,
            wrap: self.wrap,
            sss_tint: self.sss_tint,
            coat: 0.0,
        }
    }
}
