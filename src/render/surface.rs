//! What every material answers at a surface point ([`Surface`]: albedo, shading normal,
//! specular colour, roughness, metalness, wrap, coat), and sRGB byte colours as linear
//! values ([`srgb8`]). Its own file so that the materials (skin and background in
//! `material`, the line's belt in `line_surface`, distractors in `prop_material`) and the
//! tracer share it without importing each other.

use glam::Vec3;

/// What the integrator needs to know about a surface point.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub albedo: Vec3,
    pub normal: Vec3,
    /// Specular reflectance at normal incidence.
    pub f0: Vec3,
    pub roughness: f32,
    pub metallic: f32,
    /// Wrap-lighting amount (0 = Lambert); stands in for subsurface scattering.
    pub wrap: f32,
    /// Colour of light that scattered under the skin (the wrapped part).
    pub sss_tint: Vec3,
    /// Wet film: a second, sharp specular lobe (F0 at normal incidence; 0 = none).
    pub coat: f32,
}

/// Linear value of an sRGB byte triple.
pub fn srgb8(r: u8, g: u8, b: u8) -> Vec3 {
    let f = super::sensor::srgb_to_linear;
    Vec3::new(
        f(r as f32 / 255.0),
        f(g as f32 / 255.0),
        f(b as f32 / 255.0),
    )
}
