//! Procedural scenes for model tests and the model bench: filled ellipses on a plain
//! background, with their visible masks and boxes as [`Targets`]. Cheap, seeded and
//! model-neutral, so both families learn and are timed on the same input.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::annotations::targets::{ImageTargets, Targets};

/// A batch of procedural images: `[B, 3, size, size]` values in [0, 1] (row-major, channel
/// planes) and their targets. Each image has `objects` filled ellipses of random colour on a
/// plain background; later ellipses occlude earlier ones, and the masks record what stays
/// visible, so masks never overlap.
pub fn ellipse_batch(batch: usize, size: usize, objects: usize, seed: u64) -> (Vec<f32>, Targets) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pixels = vec![0f32; batch * 3 * size * size];
    let mut images = Vec::with_capacity(batch);
    let s = size as f32;
    for b in 0..batch {
        let bg: [f32; 3] = [
            rng.random_range(0.0..0.3),
            rng.random_range(0.0..0.3),
            rng.random_range(0.0..0.3),
        ];
        let mut owner = vec![0usize; size * size]; // 0 = background, k + 1 = object k
        let mut colours = Vec::new();
        for k in 0..objects {
            let rx = rng.random_range(0.08..0.22) * s;
            let ry = rng.random_range(0.08..0.22) * s;
            let cx = rng.random_range(rx..s - rx);
            let cy = rng.random_range(ry..s - ry);
            colours.push([
                rng.random_range(0.6..1.0),
                rng.random_range(0.4..1.0),
                rng.random_range(0.3..1.0),
            ]);
            for y in 0..size {
                for x in 0..size {
                    let dx = (x as f32 + 0.5 - cx) / rx;
                    let dy = (y as f32 + 0.5 - cy) / ry;
                    if dx * dx + dy * dy <= 1.0 {
                        owner[y * size + x] = k + 1;
                    }
                }
            }
        }
        let mut t = ImageTargets::default();
        for k in 0..objects {
            let mask: Vec<u8> = owner.iter().map(|&o| u8::from(o == k + 1)).collect();
            let (mut x1, mut y1, mut x2, mut y2) = (usize::MAX, usize::MAX, 0, 0);
            for (p, &m) in mask.iter().enumerate() {
                if m != 0 {
                    let (x, y) = (p % size, p / size);
                    x1 = x1.min(x);
                    y1 = y1.min(y);
                    x2 = x2.max(x + 1);
                    y2 = y2.max(y + 1);
                }
            }
            if x1 == usize::MAX {
                continue; // fully occluded
            }
            t.boxes.push([x1 as f32, y1 as f32, x2 as f32, y2 as f32]);
            t.classes.push(0);
            t.masks.push(mask);
        }
        for p in 0..size * size {
            let c = if owner[p] == 0 {
                bg
            } else {
                colours[owner[p] - 1]
            };
            for ch in 0..3 {
                pixels[((b * 3 + ch) * size * size) + p] = c[ch];
            }
        }
        images.push(t);
    }
    (pixels, Targets { images })
}
