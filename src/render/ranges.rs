//! The parameter ranges the `scene`, `distractors`, `lighting` and `camera`
//! randomisation groups draw from when they are on (`[randomize]` switches in
//! [`crate::config::Randomize`]). They widen the preset's base ranges rather than
//! replace the base look: with a group off its ranges are never read. Kept apart from the
//! base options so the base look's serialised options (and cache keys) stay as they were:
//! the defaults are left out of serialisation.

use serde::{Deserialize, Serialize};

/// Ranges of the widened groups (`ranges` in the render options).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DomainRanges {
    /// scene: probability that an image holds no carcass at all (a pure negative).
    pub p_empty: f32,
    /// scene: probability of a generic non-line background (textured / noise surface).
    pub p_generic: f32,
    /// scene: probability that the line surface is wet (darker, glossier, puddles).
    pub p_wet: f32,
    /// scene: probability of blood / fat smears on the surface.
    pub p_smears: f32,
    /// scene: probability that the pile is pushed off-centre and spread wider than the
    /// view, so carcasses are cut by the frame.
    pub p_cut: f32,
    /// distractors: number of non-carcass objects per image (inclusive range).
    pub distractors: [u32; 2],
    /// lighting: probability that the key light hangs over the view (mirrored by steel
    /// and wet surfaces: specular glare).
    pub p_glare: f32,
    /// lighting: number of lights per image, key light included (inclusive range).
    pub lights: [u32; 2],
    /// lighting: colour temperature of each light (K).
    pub light_kelvin: [f32; 2],
    /// lighting: exposure offset from auto-exposure (stops).
    pub exposure_ev: [f32; 2],
    /// lighting: camera white-balance error per red / blue channel (±).
    pub white_balance_jitter: f32,
    /// camera: height of the camera above the surface (m).
    pub camera_height: [f32; 2],
    /// camera: vertical field of view (degrees).
    pub fov_deg: [f32; 2],
    /// camera: largest tilt from straight down (degrees).
    pub tilt_max_deg: f32,
    /// camera: radial distortion k1 (negative = barrel), at the normalised image corner.
    pub lens_k1: [f32; 2],
    /// camera: radial distortion k2.
    pub lens_k2: [f32; 2],
    /// camera: probability of motion blur along the belt direction.
    pub p_motion_blur: f32,
    /// camera: motion-blur length (pixels at 640 px; scaled with the image width).
    pub motion_blur_px: [f32; 2],
    /// camera: shot-noise standard deviation at signal 1 (linear).
    pub shot_noise: [f32; 2],
    /// camera: read-noise standard deviation (linear).
    pub read_noise: [f32; 2],
    /// camera: share of the noise that is per-channel (colour noise) rather than shared.
    pub colour_noise: [f32; 2],
    /// camera: JPEG quality (inclusive range).
    pub jpeg_quality: [u8; 2],
}

impl Default for DomainRanges {
    fn default() -> Self {
        DomainRanges {
            p_empty: 0.07,
            p_generic: 0.12,
            p_wet: 0.35,
            p_smears: 0.45,
            p_cut: 0.25,
            distractors: [0, 4],
            p_glare: 0.2,
            lights: [1, 3],
            light_kelvin: [2700.0, 7500.0],
            exposure_ev: [-1.2, 1.0],
            white_balance_jitter: 0.15,
            camera_height: [0.6, 1.8],
            fov_deg: [30.0, 70.0],
            tilt_max_deg: 22.0,
            lens_k1: [-0.25, 0.08],
            lens_k2: [-0.04, 0.04],
            p_motion_blur: 0.3,
            motion_blur_px: [1.0, 8.0],
            shot_noise: [0.005, 0.06],
            read_noise: [0.0, 0.015],
            colour_noise: [0.0, 0.6],
            jpeg_quality: [40, 95],
        }
    }
}

impl DomainRanges {
    /// True for the default ranges (left out of the serialised options).
    pub fn is_default(&self) -> bool {
        *self == DomainRanges::default()
    }

    /// Rejects ranges that would panic or render nonsense, naming the field.
    pub fn validate(&self) -> anyhow::Result<()> {
        use anyhow::ensure;
        for (name, p) in [
            ("ranges.p_empty", self.p_empty),
            ("ranges.p_generic", self.p_generic),
            ("ranges.p_wet", self.p_wet),
            ("ranges.p_smears", self.p_smears),
            ("ranges.p_cut", self.p_cut),
            ("ranges.p_motion_blur", self.p_motion_blur),
            ("ranges.p_glare", self.p_glare),
        ] {
            ensure!(
                (0.0..=1.0).contains(&p),
                "{name} = {p} must be a probability in [0, 1]"
            );
        }
        let ranges: [(&str, [f32; 2], f32, f32); 10] = [
            ("ranges.light_kelvin", self.light_kelvin, 1500.0, 15000.0),
            ("ranges.exposure_ev", self.exposure_ev, -5.0, 5.0),
            ("ranges.camera_height", self.camera_height, 0.3, 5.0),
            ("ranges.fov_deg", self.fov_deg, 10.0, 100.0),
            ("ranges.lens_k1", self.lens_k1, -0.4, 0.3),
            ("ranges.lens_k2", self.lens_k2, -0.2, 0.2),
            ("ranges.motion_blur_px", self.motion_blur_px, 0.0, 40.0),
            ("ranges.shot_noise", self.shot_noise, 0.0, 0.5),
            ("ranges.read_noise", self.read_noise, 0.0, 0.2),
            ("ranges.colour_noise", self.colour_noise, 0.0, 1.0),
        ];
        for (name, r, lo, hi) in ranges {
            ensure!(
                r[0].is_finite() && r[1].is_finite() && r[0] <= r[1] && r[0] >= lo && r[1] <= hi,
                "{name} range {r:?} must be ordered and within [{lo}, {hi}]"
            );
        }
        ensure!(
            self.distractors[0] <= self.distractors[1] && self.distractors[1] <= 16,
            "ranges.distractors {:?} must be ordered with at most 16",
            self.distractors
        );
        ensure!(
            self.lights[0] >= 1 && self.lights[0] <= self.lights[1] && self.lights[1] <= 6,
            "ranges.lights {:?} must be ordered within 1-6",
            self.lights
        );
        ensure!(
            (0.0..0.5).contains(&self.white_balance_jitter),
            "ranges.white_balance_jitter {} must be in [0, 0.5)",
            self.white_balance_jitter
        );
        ensure!(
            (0.0..=45.0).contains(&self.tilt_max_deg),
            "ranges.tilt_max_deg {} must be in [0, 45]",
            self.tilt_max_deg
        );
        ensure!(
            self.jpeg_quality[0] >= 1
                && self.jpeg_quality[0] <= self.jpeg_quality[1]
                && self.jpeg_quality[1] <= 100,
            "ranges.jpeg_quality {:?} must be ordered within 1-100",
            self.jpeg_quality
        );
        // The lens must stay monotonic over the frame (r_u grows with r_d up to the corner)
        // or the warp folds the image onto itself.
        for k1 in self.lens_k1 {
            for k2 in self.lens_k2 {
                ensure!(
                    1.0 + 3.0 * k1 + 5.0 * k2 > 0.05,
                    "ranges.lens_k1 {:?} / lens_k2 {:?}: k1 = {k1}, k2 = {k2} folds the image \
                     (need 1 + 3 k1 + 5 k2 > 0.05)",
                    self.lens_k1,
                    self.lens_k2
                );
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_bad_ranges_name_the_field() {
        DomainRanges::default().validate().unwrap();
        let bad = DomainRanges {
            p_empty: 1.5,
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("p_empty"));
        let bad = DomainRanges {
            lens_k1: [-0.4, -0.35],
            lens_k2: [-0.2, -0.1],
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("lens_k1"));
        let bad = DomainRanges {
            lights: [0, 2],
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("lights"));
    }
}
