//! Lighting: one rectangular area light above the plate (soft shadows through stratified
//! shadow rays) and a room environment (dim, brighter overhead, with a glow towards the
//! key light) that metal reflects and skin receives as ambient light. Colour temperature
//! is turned into linear RGB by a blackbody fit.

use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub centre: Vec3,
    /// Half-extent vectors of the rectangle (horizontal, facing down).
    pub u: Vec3,
    pub v: Vec3,
    /// Linear RGB radiance-ish intensity (irradiance at normal incidence at 1 m / area).
    pub color: Vec3,
}

impl AreaLight {
    /// Point on the light for a stratified sample `(a, b)` in [0, 1)^2.
    #[inline]
    pub fn point(&self, a: f32, b: f32) -> Vec3 {
        self.centre + self.u * (2.0 * a - 1.0) + self.v * (2.0 * b - 1.0)
    }

    pub fn area(&self) -> f32 {
        4.0 * self.u.length() * self.v.length()
    }
}

/// The room around the rig, as seen by reflections and ambient light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Environment {
    pub ambient: Vec3,
    /// Direction towards the key light, for the glow lobe.
    pub key_dir: Vec3,
    pub glow: Vec3,
    /// Seed of the room's low-frequency structure (lamps, walls, windows) seen in steel.
    pub seed: u64,
    /// Contrast of that structure (0 = uniform room).
    pub structure: f32,
}

impl Environment {
    /// Radiance arriving from direction `d` (unit).
    #[inline]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        let up = (0.35 + 0.65 * d.z.max(0.0)).max(0.15);
        let g = d.dot(self.key_dir).max(0.0);
        let g2 = g * g;
        let room = if self.structure > 0.0 {
            let v = super::noise::fbm2(self.seed, d.x * 2.5 + 7.0, d.y * 2.5 + 7.0, 2);
            1.0 + self.structure * (v * 2.0 - 1.0)
        } else {
            1.0
        };
        self.ambient * (up * room) + self.glow * (g2 * g2 * g2 * g2)
    }
}

/// Linear sRGB colour of a blackbody at `kelvin`, normalised to unit luminance.
/// (Tanner Helland's fit, converted from sRGB to linear.)
pub fn kelvin_to_rgb(kelvin: f32) -> Vec3 {
    let t = kelvin.clamp(1000.0, 40000.0) / 100.0;
    let r = if t <= 66.0 {
        255.0
    } else {
        329.7 * (t - 60.0).powf(-0.1332)
    };
    let g = if t <= 66.0 {
        99.47 * t.ln() - 161.12
    } else {
        288.12 * (t - 60.0).powf(-0.0755)
    };
    let b = if t >= 66.0 {
        255.0
    } else if t <= 19.0 {
        0.0
    } else {
        138.52 * (t - 10.0).ln() - 305.04
    };
    let lin = |c: f32| super::sensor::srgb_to_linear((c / 255.0).clamp(0.0, 1.0));
    let c = Vec3::new(lin(r), lin(g), lin(b));
    c / c.dot(Vec3::new(0.2126, 0.7152, 0.0722)).max(1e-6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warm_is_red_cool_is_blue() {
        let warm = kelvin_to_rgb(3000.0);
        let cool = kelvin_to_rgb(9000.0);
        assert!(warm.x > warm.z && cool.z > cool.x);
        let d = kelvin_to_rgb(6500.0);
        assert!((d.x - d.z).abs() < 0.15, "{d:?}");
    }
}
