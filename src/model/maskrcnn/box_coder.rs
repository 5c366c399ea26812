//! Box ↔ delta transform of the R-CNN family (detectron2 `Box2BoxTransform`,
//! `modeling/box_regression.py`): `dx = wx·(gx − px)/pw`, `dy = wy·(gy − py)/ph`,
//! `dw = ww·ln(gw/pw)`, `dh = wh·ln(gh/ph)` with box centres and sizes, and the inverse with
//! `dw`, `dh` clamped at `ln(1000/16)` so that a wild prediction cannot overflow `exp`.
//!
//! Host-side (`f32` arrays): targets are built without gradients, and decoding only serves
//! proposals and detections, which leave the graph anyway. The regression loss compares the
//! network's raw deltas with [`BoxCoder::encode`]d targets.

/// Default `scale_clamp` of detectron2 and torchvision: `ln(1000 / 16)`.
pub fn default_scale_clamp() -> f32 {
    (1000.0f32 / 16.0).ln()
}

/// Encoder/decoder of box deltas with per-coordinate weights `(wx, wy, ww, wh)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxCoder {
    pub weights: [f32; 4],
    pub scale_clamp: f32,
}

impl BoxCoder {
    /// Panics naming the values if a weight is not finite and positive.
    pub fn new(weights: [f32; 4]) -> Self {
        assert!(
            weights.iter().all(|w| w.is_finite() && *w > 0.0),
            "BoxCoder: weights must be finite and > 0, got {weights:?}"
        );
        Self {
            weights,
            scale_clamp: default_scale_clamp(),
        }
    }

    /// RoI-head coder, weights (10, 10, 5, 5).
    pub fn roi() -> Self {
        Self::new([10.0, 10.0, 5.0, 5.0])
    }

    /// RPN coder, weights (1, 1, 1, 1).
    pub fn rpn() -> Self {
        Self::new([1.0; 4])
    }

    /// Deltas that turn `src` (xyxy) into `dst` (xyxy). `src` must have positive size.
    pub fn encode(&self, src: [f32; 4], dst: [f32; 4]) -> [f32; 4] {
        let [wx, wy, ww, wh] = self.weights;
        let (sw, sh) = (src[2] - src[0], src[3] - src[1]);
        let (sx, sy) = (src[0] + 0.5 * sw, src[1] + 0.5 * sh);
        let (dw, dh) = (dst[2] - dst[0], dst[3] - dst[1]);
        let (dx, dy) = (dst[0] + 0.5 * dw, dst[1] + 0.5 * dh);
        [
            wx * (dx - sx) / sw,
            wy * (dy - sy) / sh,
            ww * (dw / sw).ln(),
            wh * (dh / sh).ln(),
        ]
    }

    /// Box (xyxy) obtained by applying `d` to `src` (xyxy); `dw`, `dh` are clamped.
    pub fn decode(&self, d: [f32; 4], src: [f32; 4]) -> [f32; 4] {
        let [wx, wy, ww, wh] = self.weights;
        let (sw, sh) = (src[2] - src[0], src[3] - src[1]);
        let (sx, sy) = (src[0] + 0.5 * sw, src[1] + 0.5 * sh);
        let dx = d[0] / wx;
        let dy = d[1] / wy;
        let dw = (d[2] / ww).min(self.scale_clamp);
        let dh = (d[3] / wh).min(self.scale_clamp);
        let (cx, cy) = (dx * sw + sx, dy * sh + sy);
        let (w, h) = (dw.exp() * sw, dh.exp() * sh);
        [cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h]
    }
}

/// Clips an xyxy box to an image of `[height, width]` pixels.
pub fn clip_box(b: [f32; 4], [h, w]: [usize; 2]) -> [f32; 4] {
    let (w, h) = (w as f32, h as f32);
    [
        b[0].clamp(0.0, w),
        b[1].clamp(0.0, h),
        b[2].clamp(0.0, w),
        b[3].clamp(0.0, h),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f32; 4], b: [f32; 4], tol: f32) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn encode_hand_values() {
        let c = BoxCoder::roi();
        // src centre (15, 30), size 10×20; dst centre (20, 25), size 20×10.
        let d = c.encode([10.0, 20.0, 20.0, 40.0], [10.0, 20.0, 30.0, 30.0]);
        let expect = [
            10.0 * 5.0 / 10.0,
            10.0 * -5.0 / 20.0,
            5.0 * 2f32.ln(),
            5.0 * 0.5f32.ln(),
        ];
        assert!(close(d, expect, 1e-5), "{d:?} vs {expect:?}");
        // Identity.
        let z = c.encode([1.0, 2.0, 5.0, 9.0], [1.0, 2.0, 5.0, 9.0]);
        assert!(close(z, [0.0; 4], 1e-6), "{z:?}");
    }

    #[test]
    fn round_trip() {
        for coder in [BoxCoder::roi(), BoxCoder::rpn()] {
            let src = [12.5, -3.0, 80.0, 41.0];
            for dst in [
                [0.0, 0.0, 10.0, 10.0],
                [30.0, 20.0, 200.0, 90.5],
                [11.0, -5.0, 12.0, -4.0],
            ] {
                let back = coder.decode(coder.encode(src, dst), src);
                assert!(close(back, dst, 1e-3), "{back:?} vs {dst:?}");
            }
        }
    }

    #[test]
    fn decode_clamps_scale() {
        let c = BoxCoder::rpn();
        let b = c.decode([0.0, 0.0, 100.0, 100.0], [0.0, 0.0, 16.0, 16.0]);
        // exp(ln(1000/16)) · 16 = 1000 px wide, centred on 8.
        assert!(close(b, [-492.0, -492.0, 508.0, 508.0], 1e-2), "{b:?}");
        assert!(b.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn clip() {
        assert_eq!(
            clip_box([-5.0, 3.0, 70.0, 90.0], [64, 48]),
            [0.0, 3.0, 48.0, 64.0]
        );
    }

    #[test]
    #[should_panic(expected = "weights must be finite and > 0, got [10.0, 0.0, 5.0, 5.0]")]
    fn rejects_zero_weight() {
        BoxCoder::new([10.0, 0.0, 5.0, 5.0]);
    }
}
