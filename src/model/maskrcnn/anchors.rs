//! Anchor generation per FPN level (detectron2 `DefaultAnchorGenerator`, offset 0): one size
//! per level, several aspect ratios; cell anchors centred on `(x·stride, y·stride)`.
//!
//! Ordering (matches the RPN head's flattening): levels finest first, then grid rows, grid
//! columns, then the cell anchors (ratios) of that location.

use serde::{Deserialize, Serialize};

/// Anchor sizes (one per level, in input pixels) and aspect ratios `h / w`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorConfig {
    pub sizes: Vec<f32>,
    pub ratios: Vec<f32>,
}

impl AnchorConfig {
    /// The paper's anchors: 32…512 on P2…P6, ratios 0.5 / 1 / 2.
    pub fn paper() -> Self {
        Self {
            sizes: vec![32.0, 64.0, 128.0, 256.0, 512.0],
            ratios: vec![0.5, 1.0, 2.0],
        }
    }

    /// Scene-sized anchors for top-view carcass piles at ~320–512 px input: carcasses span
    /// roughly 40–250 px there, so the ladder starts at 24 px instead of 32 and the P6
    /// anchors stay within the image.
    pub fn compact() -> Self {
        Self {
            sizes: vec![24.0, 48.0, 96.0, 192.0, 384.0],
            ratios: vec![0.5, 1.0, 2.0],
        }
    }

    /// Panics naming the values unless there is one positive size per level and positive
    /// ratios.
    pub fn validate(&self, num_levels: usize) {
        assert!(
            self.sizes.len() == num_levels && self.sizes.iter().all(|s| s.is_finite() && *s > 0.0),
            "AnchorConfig: need {num_levels} positive sizes (one per level), got {:?}",
            self.sizes
        );
        assert!(
            !self.ratios.is_empty() && self.ratios.iter().all(|r| r.is_finite() && *r > 0.0),
            "AnchorConfig: ratios must be non-empty and positive, got {:?}",
            self.ratios
        );
    }

    pub fn per_location(&self) -> usize {
        self.ratios.len()
    }

    /// Cell anchors of one level, centred on the origin: `w = √(s²/r)`, `h = r·w`.
    pub fn cell_anchors(&self, level: usize) -> Vec<[f32; 4]> {
        let s = self.sizes[level];
        self.ratios
            .iter()
            .map(|&r| {
                let w = (s * s / r).sqrt();
                let h = r * w;
                [-0.5 * w, -0.5 * h, 0.5 * w, 0.5 * h]
            })
            .collect()
    }

    /// All anchors of the levels `(stride, height, width)`, in the order documented above.
    pub fn generate(&self, levels: &[(usize, usize, usize)]) -> Vec<Vec<[f32; 4]>> {
        levels
            .iter()
            .enumerate()
            .map(|(l, &(stride, h, w))| {
                let cells = self.cell_anchors(l);
                let mut v = Vec::with_capacity(h * w * cells.len());
                for y in 0..h {
                    for x in 0..w {
                        let (sx, sy) = ((x * stride) as f32, (y * stride) as f32);
                        for c in &cells {
                            v.push([c[0] + sx, c[1] + sy, c[2] + sx, c[3] + sy]);
                        }
                    }
                }
                v
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_anchors_hand_values() {
        let a = AnchorConfig::paper().cell_anchors(0);
        // size 32: ratio 0.5 → w = √2048 ≈ 45.25, h ≈ 22.63; ratio 1 → 32 × 32.
        let w = (2048f32).sqrt();
        assert!((a[0][2] - a[0][0] - w).abs() < 1e-4 && (a[0][3] - a[0][1] - 0.5 * w).abs() < 1e-4);
        assert_eq!(a[1], [-16.0, -16.0, 16.0, 16.0]);
        for c in &a {
            let area = (c[2] - c[0]) * (c[3] - c[1]);
            assert!((area - 1024.0).abs() < 1e-2, "area {area}");
        }
    }

    #[test]
    fn grid_order_and_count() {
        let cfg = AnchorConfig::paper();
        let all = cfg.generate(&[(4, 2, 3), (8, 1, 2)]);
        assert_eq!(all[0].len(), 2 * 3 * 3);
        assert_eq!(all[1].len(), 2 * 3);
        // Location (y 1, x 2) of level 0, square anchor: centred at (8, 4).
        assert_eq!(all[0][(3 + 2) * 3 + 1], [-8.0, -12.0, 24.0, 20.0]);
        // Level 1 uses the second size (64): square anchor at (8, 0).
        assert_eq!(all[1][3 + 1], [-24.0, -32.0, 40.0, 32.0]);
    }

    #[test]
    #[should_panic(expected = "need 5 positive sizes (one per level), got [32.0, 64.0]")]
    fn rejects_size_count() {
        AnchorConfig {
            sizes: vec![32.0, 64.0],
            ratios: vec![1.0],
        }
        .validate(5);
    }
}
