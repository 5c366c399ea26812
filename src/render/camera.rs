//! The top-view pinhole camera: position above the plate, a tilt of up to ±10° from
//! straight down, a random roll (image rotation) and a vertical field of view. Primary
//! rays for the tracer and the matching projection for the amodal-mask rasteriser come
//! from the same basis, so both agree on which pixel centre sees which point.

use glam::{Quat, Vec2, Vec3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    /// Camera basis: `right` (image +x), `down` (image +y) and `forward` (view axis).
    pub right: Vec3,
    pub down: Vec3,
    pub forward: Vec3,
    /// tan(fov_y / 2).
    pub tan_half: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Looks down -z from `eye`, tilted by `tilt` radians about a horizontal axis at
    /// azimuth `tilt_dir`, rolled by `roll` radians about the view axis.
    pub fn top_view(
        eye: Vec3,
        tilt: f32,
        tilt_dir: f32,
        roll: f32,
        fov_y: f32,
        width: u32,
        height: u32,
    ) -> Camera {
        let axis = Vec3::new(tilt_dir.cos(), tilt_dir.sin(), 0.0);
        let q = Quat::from_axis_angle(axis, tilt) * Quat::from_rotation_z(roll);
        Camera {
            eye,
            right: q * Vec3::X,
            down: q * Vec3::NEG_Y,
            forward: q * Vec3::NEG_Z,
            tan_half: (fov_y * 0.5).tan(),
            width,
            height,
        }
    }

    /// Unit direction through image point (px, py) (pixel centres at +0.5).
    #[inline]
    pub fn dir(&self, px: f32, py: f32) -> Vec3 {
        let h = self.height as f32;
        let sx = (2.0 * px - self.width as f32) / h * self.tan_half;
        let sy = (2.0 * py - h) / h * self.tan_half;
        (self.forward + self.right * sx + self.down * sy).normalize()
    }

    /// Image position of a world point, or None behind the camera.
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let d = p - self.eye;
        let z = d.dot(self.forward);
        if z <= 1e-6 {
            return None;
        }
        let h = self.height as f32;
        let sx = d.dot(self.right) / z / self.tan_half;
        let sy = d.dot(self.down) / z / self.tan_half;
        Some(Vec2::new(
            (sx * h + self.width as f32) * 0.5,
            (sy * h + h) * 0.5,
        ))
    }

    /// Where the plate (z = 0) is seen at image point (px, py), if it is.
    pub fn plate_point(&self, px: f32, py: f32) -> Option<Vec3> {
        let d = self.dir(px, py);
        (d.z < -1e-6).then(|| self.eye + d * (-self.eye.z / d.z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_dir_under_tilt_and_roll() {
        let c = Camera::top_view(Vec3::new(0.1, -0.2, 1.1), 0.15, 0.7, 2.0, 0.8, 96, 64);
        for (px, py) in [(0.5, 0.5), (47.5, 31.5), (95.5, 10.25)] {
            let p = c.eye + c.dir(px, py) * 1.3;
            let q = c.project(p).unwrap();
            assert!((q - Vec2::new(px, py)).length() < 1e-3, "{q:?}");
        }
        assert!(c.project(c.eye - c.forward).is_none());
        // Straight down, untilted: the image centre sees the point below the eye.
        let c = Camera::top_view(Vec3::new(0.0, 0.0, 1.0), 0.0, 0.0, 0.0, 0.8, 64, 64);
        assert!(c.plate_point(32.0, 32.0).unwrap().truncate().length() < 1e-5);
    }
}
