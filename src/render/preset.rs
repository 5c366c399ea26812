//! Render options and the two presets.
//!
//! * `synthetic`: the paper's rendered domain, widely randomised (light, exposure, white
//!   balance, camera, poses, density isolated → overlapped, belt and stains sometimes).
//! * `proxy-real`: a PROXY for the paper's 300 real photographs, which are not available.
//!   It is a distinct, more photographic domain: a fixed studio rig (a large soft box to
//!   one side at about 45°, out of the steel's mirror view; neutral-warm light; matte
//!   2B-finish steel), a longer lens from higher up with less tilt, stronger
//!   sensor noise, blur and JPEG compression, a camera white-balance error, steel only,
//!   narrower shape ranges, and its own seed space. It stands in for real data in
//!   experiments and is called a proxy wherever it appears; real LabelMe/COCO data
//!   replaces it through the config.
//!
//! Options deserialize with `deny_unknown_fields` and are checked by [`RenderOptions::validate`].

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::labels::LabelThresholds;
use super::ranges::DomainRanges;
use super::skin::PoseRanges;
use crate::config::{Negatives, Randomize};

/// Image file format of rendered datasets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImageFormat {
    Jpg,
    Png,
}

/// Everything that determines a rendered dataset (with the seed and the image index).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderOptions {
    /// "synthetic" or "proxy-real" (recorded in metadata; also picks the seed space).
    pub preset: String,
    pub width: u32,
    pub height: u32,
    /// Number of images `render_dataset` writes.
    pub count: u32,
    pub seed: u64,
    /// Carcass mesh (.glb); None = the embedded procedural carcass.
    pub carcass: Option<PathBuf>,
    /// Carcasses per image (inclusive range).
    pub carcasses: [u32; 2],
    /// Pile density range: 0 isolated, 0.5 tightly clustered, 1 overlapped.
    pub density: [f32; 2],
    /// Pile centre offset from the view centre, as a fraction of the half view.
    pub pile_offset: f32,
    /// Weights of breast-up, breast-down, side.
    pub resting_weights: [f32; 3],
    pub pose: PoseRanges,
    /// 0 = pink-white skin, 1 = yellow (corn-fed).
    pub skin_yellow: [f32; 2],
    pub camera_height: [f32; 2],
    pub fov_deg: [f32; 2],
    pub tilt_max_deg: f32,
    pub light_height: [f32; 2],
    pub light_size: [f32; 2],
    /// Horizontal offset range of the key light from the view centre (m). Offsets
    /// beyond about half the view keep the soft box's mirror image off the steel.
    pub light_offset: [f32; 2],
    pub light_kelvin: [f32; 2],
    /// Room ambient relative to the key light.
    pub ambient: [f32; 2],
    pub exposure_ev: [f32; 2],
    pub white_balance_jitter: f32,
    /// How much of the light's colour cast the camera's white balance removes (0-1).
    pub white_balance_correction: [f32; 2],
    pub vignette: [f32; 2],
    pub blur_px: [f32; 2],
    pub shot_noise: [f32; 2],
    pub format: ImageFormat,
    pub jpeg_quality: [u8; 2],
    pub p_belt: f32,
    pub p_stains: f32,
    /// Roughness range of the stainless plate (0.2 polished … 0.5 matte 2B finish).
    pub steel_roughness: [f32; 2],
    /// Shadow rays per pixel (stratified over the area light).
    pub shadow_samples: u32,
    /// Radius of the edge-aware shadow-visibility filter in pixels (0 = off).
    pub shadow_filter_px: u32,
    /// Glossy reflection rays on the steel.
    pub reflections: bool,
    /// Primary visibility by z-buffer rasterisation instead of primary rays (same result
    /// up to ties at triangle edges, several times faster).
    pub raster_primary: bool,
    pub labels: LabelThresholds,
    /// Domain-randomisation groups switched on (see [`Randomize`]); all off renders the
    /// base look, and is left out of the serialised options (and so of cache keys).
    #[serde(default, skip_serializing_if = "Randomize::is_off")]
    pub randomize: Randomize,
    /// Ranges the `scene`, `distractors`, `lighting` and `camera` groups draw from when
    /// on (see [`DomainRanges`]); left out of the serialised options while default.
    #[serde(default, skip_serializing_if = "DomainRanges::is_default")]
    pub ranges: DomainRanges,
    /// Shares of carcass-free renders and renders with distractors (see [`Negatives`]);
    /// both 0 renders as before and is left out of the serialised options (cache keys).
    #[serde(default, skip_serializing_if = "Negatives::is_off")]
    pub negatives: Negatives,
}

impl RenderOptions {
    /// The rendered training domain.
    pub fn synthetic(size: u32) -> RenderOptions {
        RenderOptions {
            preset: "synthetic".into(),
            width: size,
            height: size,
            count: 1000,
            seed: 0,
            carcass: None,
            carcasses: [1, 12],
            density: [0.0, 1.0],
            pile_offset: 0.3,
            resting_weights: [0.5, 0.3, 0.2],
            pose: PoseRanges::default(),
            skin_yellow: [0.0, 1.0],
            camera_height: [0.85, 1.3],
            fov_deg: [38.0, 55.0],
            tilt_max_deg: 10.0,
            light_height: [1.0, 2.2],
            light_size: [0.3, 1.2],
            light_offset: [1.2, 2.5],
            light_kelvin: [3200.0, 6800.0],
            ambient: [0.15, 0.6],
            exposure_ev: [-0.5, 0.5],
            white_balance_jitter: 0.08,
            white_balance_correction: [0.4, 0.95],
            vignette: [0.0, 0.35],
            blur_px: [0.3, 0.9],
            shot_noise: [0.005, 0.03],
            format: ImageFormat::Jpg,
            jpeg_quality: [85, 95],
            p_belt: 0.15,
            p_stains: 0.35,
            steel_roughness: [0.18, 0.45],
            shadow_samples: 1,
            shadow_filter_px: 4,
            reflections: true,
            raster_primary: true,
            labels: LabelThresholds::default(),
            randomize: Randomize::default(),
            ranges: DomainRanges::default(),
            negatives: Negatives::default(),
        }
    }

    /// The PROXY for the paper's real photographs (see the module docs).
    pub fn proxy_real(size: u32) -> RenderOptions {
        RenderOptions {
            preset: "proxy-real".into(),
            count: 300,
            carcasses: [1, 8],
            density: [0.1, 0.9],
            pile_offset: 0.15,
            resting_weights: [0.6, 0.3, 0.1],
            pose: PoseRanges {
                scale: [0.95, 1.08],
                asymmetry: 0.05,
                wing_spread: [-0.3, 0.3],
                leg_splay: [-0.1, 0.3],
                knee_bend: [-0.15, 0.2],
                displacement_mm: [1.5, 3.0],
                p_missing_tip: 0.03,
            },
            skin_yellow: [0.2, 0.7],
            camera_height: [1.15, 1.35],
            fov_deg: [34.0, 40.0],
            tilt_max_deg: 4.0,
            light_height: [1.3, 1.5],
            light_size: [0.9, 1.1],
            light_offset: [1.3, 1.6],
            light_kelvin: [4300.0, 5000.0],
            ambient: [0.3, 0.4],
            exposure_ev: [-0.2, 0.3],
            white_balance_jitter: 0.04,
            white_balance_correction: [0.7, 0.8],
            vignette: [0.2, 0.35],
            blur_px: [0.7, 1.1],
            shot_noise: [0.02, 0.04],
            jpeg_quality: [70, 85],
            p_belt: 0.0,
            p_stains: 0.2,
            steel_roughness: [0.35, 0.5],
            ..RenderOptions::synthetic(size)
        }
    }

    /// A preset by CLI name.
    pub fn preset(name: &str, size: u32) -> anyhow::Result<RenderOptions> {
        match name {
            "synthetic" => Ok(Self::synthetic(size)),
            "proxy-real" => Ok(Self::proxy_real(size)),
            other => anyhow::bail!(
                "unknown render preset {other:?}; expected \"synthetic\" or \"proxy-real\""
            ),
        }
    }

    /// Seed-space tag: proxy-real images never share an RNG stream with synthetic ones.
    pub fn domain(&self) -> u64 {
        match self.preset.as_str() {
            "proxy-real" => 0x9E0C_7EA1,
            _ => 0x5D17_E71C,
        }
    }

    /// The JPEG qualities an image is saved at (rendered scenes and clutter pictures draw
    /// from it); ordered even for options that skipped `validate`, so a draw never panics.
    pub fn jpeg_quality_range(&self) -> std::ops::RangeInclusive<u8> {
        let q = self.jpeg_quality;
        q[0].min(q[1])..=q[1].max(q[0])
    }

    /// True for the proxy-real preset (label it as a proxy in every report).
    pub fn is_proxy(&self) -> bool {
        self.preset == "proxy-real"
    }

    /// Rejects options that would panic or render nonsense, naming the field.
    pub fn validate(&self) -> anyhow::Result<()> {
        use anyhow::ensure;
        ensure!(
            (16..=8192).contains(&self.width) && (16..=8192).contains(&self.height),
            "render size {}x{} out of range (16-8192)",
            self.width,
            self.height
        );
        ensure!(
            self.carcasses[0] >= 1
                && self.carcasses[0] <= self.carcasses[1]
                && self.carcasses[1] <= 64,
            "carcasses range {:?} must be 1 <= lo <= hi <= 64",
            self.carcasses
        );
        let ranges: [(&str, [f32; 2], f32, f32); 16] = [
            ("density", self.density, 0.0, 1.0),
            ("skin_yellow", self.skin_yellow, 0.0, 1.0),
            ("camera_height", self.camera_height, 0.3, 5.0),
            ("fov_deg", self.fov_deg, 10.0, 100.0),
            ("light_height", self.light_height, 0.3, 10.0),
            ("light_size", self.light_size, 0.01, 5.0),
            ("light_kelvin", self.light_kelvin, 1500.0, 15000.0),
            ("ambient", self.ambient, 0.0, 5.0),
            ("exposure_ev", self.exposure_ev, -5.0, 5.0),
            ("vignette", self.vignette, 0.0, 0.9),
            ("blur_px", self.blur_px, 0.0, 5.0),
            ("shot_noise", self.shot_noise, 0.0, 0.5),
            ("pose.scale", self.pose.scale, 0.5, 2.0),
            ("pose.displacement_mm", self.pose.displacement_mm, 0.0, 20.0),
            ("steel_roughness", self.steel_roughness, 0.05, 1.0),
            (
                "white_balance_correction",
                self.white_balance_correction,
                0.0,
                1.0,
            ),
        ];
        for (name, r, lo, hi) in ranges {
            ensure!(
                r[0].is_finite() && r[1].is_finite() && r[0] <= r[1] && r[0] >= lo && r[1] <= hi,
                "{name} range {r:?} must be ordered and within [{lo}, {hi}]"
            );
        }
        ensure!(
            (0.0..=1.0).contains(&self.p_belt) && (0.0..=1.0).contains(&self.p_stains),
            "p_belt and p_stains must be probabilities"
        );
        ensure!(
            (0.0..=1.0).contains(&self.pose.p_missing_tip),
            "pose.p_missing_tip must be a probability"
        );
        ensure!(
            (0.0..=45.0).contains(&self.tilt_max_deg),
            "tilt_max_deg {} must be in [0, 45]",
            self.tilt_max_deg
        );
        ensure!(
            self.resting_weights.iter().all(|w| *w >= 0.0)
                && self.resting_weights.iter().sum::<f32>() > 0.0,
            "resting_weights must be non-negative and not all zero"
        );
        ensure!(
            self.jpeg_quality[0] >= 1
                && self.jpeg_quality[0] <= self.jpeg_quality[1]
                && self.jpeg_quality[1] <= 100,
            "jpeg_quality range {:?} must be ordered within 1-100",
            self.jpeg_quality
        );
        ensure!(
            (1..=64).contains(&self.shadow_samples),
            "shadow_samples must be 1-64"
        );
        ensure!(self.shadow_filter_px <= 32, "shadow_filter_px must be 0-32");
        ensure!(
            (0.0..=2.0).contains(&self.pile_offset),
            "pile_offset must be in [0, 2]"
        );
        ensure!(
            self.light_offset[0] >= 0.0
                && self.light_offset[0] <= self.light_offset[1]
                && self.light_offset[1] <= 10.0,
            "light_offset range {:?} must be ordered within [0, 10]",
            self.light_offset
        );
        ensure!(
            self.white_balance_jitter >= 0.0 && self.white_balance_jitter < 0.5,
            "white_balance_jitter must be in [0, 0.5)"
        );
        self.ranges.validate()?;
        self.negatives.validate()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate_and_differ() {
        let s = RenderOptions::synthetic(640);
        let p = RenderOptions::proxy_real(640);
        s.validate().unwrap();
        p.validate().unwrap();
        assert_ne!(s.domain(), p.domain());
        assert!(p.is_proxy() && !s.is_proxy());
        assert!(RenderOptions::preset("real", 64).is_err());
        let mut bad = s.clone();
        bad.density = [0.8, 0.2];
        assert!(bad.validate().unwrap_err().to_string().contains("density"));
        // Unknown keys are rejected.
        let mut v = serde_json::to_value(&s).unwrap();
        v["densty"] = serde_json::json!(1);
        assert!(serde_json::from_value::<RenderOptions>(v).is_err());
    }
}
