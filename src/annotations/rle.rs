//! Run-length encoded masks, byte-identical to pycocotools' `maskApi.c`.
//!
//! The evaluator, the renderer's labels and the data loaders all meet here, so every
//! function is a line-by-line port of its C counterpart (`rleEncode`, `rleToString`,
//! `rleFrString`, `rleMerge`, `rleArea`, `rleToBbox`, `rleIou`, `bbIou`), including the
//! unsigned wrap-arounds, so that areas, boxes and IoUs agree bit for bit.

use super::mask::{CroppedMask, Mask};

/// Why an RLE could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RleError {
    #[error("RLE string has a character {0:?} outside the COCO alphabet ('0'..='o')")]
    BadChar(char),
    #[error("RLE string ends in the middle of a number")]
    Truncated,
    #[error("RLE run lengths sum to {sum} but its size {height}x{width} has {expected} pixels")]
    WrongTotal {
        sum: u64,
        height: u32,
        width: u32,
        expected: u64,
    },
}

/// Column-major run lengths, starting with a (possibly empty) background run.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct Rle {
    pub height: u32,
    pub width: u32,
    pub counts: Vec<u32>,
}

impl Rle {
    /// `rleEncode`: runs over the column-major pixels of a row-major mask.
    pub fn encode(mask: &Mask) -> Rle {
        let (h, w) = (mask.height as usize, mask.width as usize);
        let mut counts = Vec::new();
        let (mut prev, mut run) = (false, 0u32);
        for x in 0..w {
            for y in 0..h {
                let v = mask.data[y * w + x] != 0;
                if v != prev {
                    counts.push(run);
                    run = 0;
                    prev = v;
                }
                run += 1;
            }
        }
        counts.push(run);
        Rle {
            height: mask.height,
            width: mask.width,
            counts,
        }
    }

    /// The same runs as `encode(&m.full())`, walking only the window's columns: the
    /// columns left and right of it and the rows above and below it are background runs.
    pub fn encode_cropped(m: &CroppedMask) -> Rle {
        let (h, w) = (m.height as u64, m.width as u64);
        let (ww, wh) = (m.window.width as usize, m.window.height as usize);
        assert!(
            m.x0 as u64 + ww as u64 <= w && m.y0 as u64 + wh as u64 <= h,
            "encode_cropped: window {ww}×{wh} at ({}, {}) leaves the {w}×{h} image",
            m.x0,
            m.y0
        );
        let mut counts = Vec::new();
        let (mut prev, mut run) = (false, 0u64);
        let mut push = |v: bool, n: u64| {
            if n == 0 {
                return;
            }
            if v != prev {
                counts.push(run as u32);
                run = 0;
                prev = v;
            }
            run += n;
        };
        push(false, m.x0 as u64 * h);
        let below = h - m.y0 as u64 - wh as u64;
        for x in 0..ww {
            push(false, m.y0 as u64);
            for y in 0..wh {
                push(m.window.data[y * ww + x] != 0, 1);
            }
            push(false, below);
        }
        push(false, (w - m.x0 as u64 - ww as u64) * h);
        counts.push(run as u32);
        Rle {
            height: m.height,
            width: m.width,
            counts,
        }
    }

    /// Builds an RLE from uncompressed counts, checking that they cover the image exactly.
    pub fn from_counts(height: u32, width: u32, counts: Vec<u32>) -> Result<Rle, RleError> {
        let rle = Rle {
            height,
            width,
            counts,
        };
        rle.check_total()?;
        Ok(rle)
    }

    /// Run lengths must add up to h·w, or decoding would read past the image.
    pub fn check_total(&self) -> Result<(), RleError> {
        let sum: u64 = self.counts.iter().map(|&c| c as u64).sum();
        let expected = self.height as u64 * self.width as u64;
        if sum != expected {
            return Err(RleError::WrongTotal {
                sum,
                height: self.height,
                width: self.width,
                expected,
            });
        }
        Ok(())
    }

    /// Back to a row-major mask.
    pub fn decode(&self) -> Mask {
        let (h, w) = (self.height as usize, self.width as usize);
        let mut mask = Mask::new(self.height, self.width);
        let mut pos = 0usize;
        let mut on = false;
        for &c in &self.counts {
            if on {
                for p in pos..(pos + c as usize).min(h * w) {
                    let (x, y) = (p / h, p % h);
                    mask.data[y * w + x] = 1;
                }
            }
            pos += c as usize;
            on = !on;
        }
        mask
    }

    /// `rleToString`: the compressed COCO string (LEB128-like, delta to the run two back).
    pub fn to_compressed(&self) -> String {
        let mut s = String::with_capacity(self.counts.len() * 2);
        for (i, &c) in self.counts.iter().enumerate() {
            let mut x = c as i64;
            if i > 2 {
                x -= self.counts[i - 2] as i64;
            }
            let mut more = true;
            while more {
                let mut ch = (x & 0x1f) as u8;
                x >>= 5;
                more = if ch & 0x10 != 0 { x != -1 } else { x != 0 };
                if more {
                    ch |= 0x20;
                }
                s.push((ch + 48) as char);
            }
        }
        s
    }

    /// `rleFrString` with the counts checked against the size.
    pub fn from_compressed(s: &str, height: u32, width: u32) -> Result<Rle, RleError> {
        let rle = Rle {
            height,
            width,
            counts: decode_counts(s)?,
        };
        rle.check_total()?;
        Ok(rle)
    }

    /// `rleArea`: the sum of the foreground runs.
    pub fn area(&self) -> u64 {
        self.counts
            .iter()
            .skip(1)
            .step_by(2)
            .map(|&c| c as u64)
            .sum()
    }

    /// `rleToBbox`: [x, y, w, h] of the foreground, zeros when empty.
    pub fn bbox(&self) -> [f64; 4] {
        let (h, w) = (self.height, self.width);
        let m = self.counts.len() / 2 * 2;
        if m == 0 || h == 0 {
            return [0.0; 4];
        }
        let (mut xs, mut ys, mut xe, mut ye) = (w, h, 0u32, 0u32);
        let (mut cc, mut xp) = (0u32, 0u32);
        for j in 0..m {
            cc = cc.wrapping_add(self.counts[j]);
            let t = cc.wrapping_sub((j % 2) as u32);
            let y = t % h;
            let x = (t - y) / h;
            if j % 2 == 0 {
                xp = x;
            } else if xp < x {
                ys = 0;
                ye = h - 1;
            }
            xs = xs.min(x);
            xe = xe.max(x);
            ys = ys.min(y);
            ye = ye.max(y);
        }
        [
            xs as f64,
            ys as f64,
            xe.wrapping_sub(xs).wrapping_add(1) as f64,
            ye.wrapping_sub(ys).wrapping_add(1) as f64,
        ]
    }

    /// `rleMerge`: union (or intersection) of masks of one size; mismatched sizes give an
    /// empty 0×0 RLE, as in pycocotools.
    pub fn merge(rles: &[Rle], intersect: bool) -> Rle {
        let Some(first) = rles.first() else {
            return Rle::default();
        };
        if rles.len() == 1 {
            return first.clone();
        }
        let (mut h, mut w) = (first.height, first.width);
        let mut cnts = first.counts.clone();
        for b_rle in &rles[1..] {
            if b_rle.height != h || b_rle.width != w {
                h = 0;
                w = 0;
                cnts.clear();
                break;
            }
            let a_rle = std::mem::take(&mut cnts);
            let (am, bm) = (a_rle.len(), b_rle.counts.len());
            let mut ca = a_rle.first().copied().unwrap_or(0);
            let mut cb = b_rle.counts.first().copied().unwrap_or(0);
            let (mut v, mut va, mut vb) = (false, false, false);
            let (mut a, mut b) = (1usize, 1usize);
            let (mut cc, mut ct) = (0u32, 1u32);
            while ct > 0 {
                let c = ca.min(cb);
                cc = cc.wrapping_add(c);
                ct = 0;
                ca -= c;
                if ca == 0 && a < am {
                    ca = a_rle[a];
                    a += 1;
                    va = !va;
                }
                ct = ct.wrapping_add(ca);
                cb -= c;
                if cb == 0 && b < bm {
                    cb = b_rle.counts[b];
                    b += 1;
                    vb = !vb;
                }
                ct = ct.wrapping_add(cb);
                let vp = v;
                v = if intersect { va && vb } else { va || vb };
                if v != vp || ct == 0 {
                    cnts.push(cc);
                    cc = 0;
                }
            }
        }
        Rle {
            height: h,
            width: w,
            counts: cnts,
        }
    }
}

/// The counts of a compressed string, as `rleFrString` reads them.
fn decode_counts(s: &str) -> Result<Vec<u32>, RleError> {
    let bytes = s.as_bytes();
    let mut counts: Vec<u32> = Vec::with_capacity(bytes.len());
    let mut p = 0;
    while p < bytes.len() {
        let (mut x, mut k, mut more) = (0i64, 0u32, true);
        while more {
            let Some(&byte) = bytes.get(p) else {
                return Err(RleError::Truncated);
            };
            if !(48..48 + 64).contains(&byte) {
                return Err(RleError::BadChar(s[p..].chars().next().unwrap_or('?')));
            }
            let c = (byte - 48) as i64;
            if 5 * k >= 63 {
                return Err(RleError::Truncated);
            }
            x |= (c & 0x1f) << (5 * k);
            more = c & 0x20 != 0;
            p += 1;
            k += 1;
            if !more && (c & 0x10) != 0 {
                // Sign extension; past bit 63 there is nothing left to set (a plain `<<`
                // overflows there: found by the `rle` fuzz target).
                x |= (-1i64).checked_shl(5 * k).unwrap_or(0);
            }
        }
        let m = counts.len();
        if m > 2 {
            x += counts[m - 2] as i64;
        }
        counts.push(x as u32);
    }
    Ok(counts)
}

/// `bbIou`: IoU of [x, y, w, h] boxes; a crowd GT divides by the detection's area only.
#[inline]
pub fn bbox_iou(d: &[f64; 4], g: &[f64; 4], crowd: bool) -> f64 {
    let w = (d[2] + d[0]).min(g[2] + g[0]) - d[0].max(g[0]);
    if w <= 0.0 {
        return 0.0;
    }
    let h = (d[3] + d[1]).min(g[3] + g[1]) - d[1].max(g[1]);
    if h <= 0.0 {
        return 0.0;
    }
    let i = w * h;
    let da = d[2] * d[3];
    let u = if crowd { da } else { da + g[2] * g[3] - i };
    i / u
}

/// `rleIou` for one pair, given both boxes (the C code filters by box IoU first):
/// −1 when the sizes differ, as pycocotools does.
pub fn rle_iou(dt: &Rle, dt_box: &[f64; 4], gt: &Rle, gt_box: &[f64; 4], crowd: bool) -> f64 {
    if bbox_iou(dt_box, gt_box, crowd) <= 0.0 {
        return 0.0;
    }
    if dt.height != gt.height || dt.width != gt.width {
        return -1.0;
    }
    let (ka, kb) = (dt.counts.len(), gt.counts.len());
    let mut ca = dt.counts.first().copied().unwrap_or(0);
    let mut cb = gt.counts.first().copied().unwrap_or(0);
    let (mut va, mut vb) = (false, false);
    let (mut a, mut b) = (1usize, 1usize);
    let (mut i, mut u, mut ct) = (0u32, 0u32, 1u32);
    while ct > 0 {
        let c = ca.min(cb);
        if va || vb {
            u = u.wrapping_add(c);
            if va && vb {
                i = i.wrapping_add(c);
            }
        }
        ct = 0;
        ca -= c;
        if ca == 0 && a < ka {
            ca = dt.counts[a];
            a += 1;
            va = !va;
        }
        ct = ct.wrapping_add(ca);
        cb -= c;
        if cb == 0 && b < kb {
            cb = gt.counts[b];
            b += 1;
            vb = !vb;
        }
        ct = ct.wrapping_add(cb);
    }
    if i == 0 {
        u = 1;
    } else if crowd {
        u = dt.area() as u32;
    }
    i as f64 / u as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(h: u32, w: u32, on: &[(u32, u32)]) -> Mask {
        let mut m = Mask::new(h, w);
        for &(x, y) in on {
            m.set(x, y, true);
        }
        m
    }

    #[test]
    fn notes_example_round_trips() {
        // anchors.md: counts [5, 2, 2, 2, 5] <-> "52203"
        let rle = Rle {
            height: 4,
            width: 4,
            counts: vec![5, 2, 2, 2, 5],
        };
        assert_eq!(rle.to_compressed(), "52203");
        assert_eq!(Rle::from_compressed("52203", 4, 4).unwrap(), rle);
    }

    #[test]
    fn cropped_encoding_equals_encoding_the_full_mask() {
        // Windows at every edge, empty and full windows, and a 0-pixel window; pixels from
        // a fixed-seed LCG.
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut bit = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 61) & 1 == 1
        };
        let (w, h) = (9u32, 7u32);
        for (x0, y0, ww, wh) in [
            (0, 0, 9, 7),
            (0, 0, 3, 2),
            (6, 5, 3, 2),
            (2, 1, 4, 5),
            (8, 0, 1, 7),
            (0, 6, 9, 1),
            (4, 3, 0, 0),
        ] {
            for fill in [None, Some(0u8), Some(1u8)] {
                let data = (0..ww * wh)
                    .map(|_| fill.unwrap_or_else(|| bit() as u8))
                    .collect();
                let c = CroppedMask {
                    width: w,
                    height: h,
                    x0,
                    y0,
                    window: Mask::from_row_major(wh, ww, data).unwrap(),
                };
                let full = c.full();
                assert_eq!(
                    Rle::encode_cropped(&c),
                    Rle::encode(&full),
                    "{x0} {y0} {ww} {wh}"
                );
                assert_eq!(c.area(), full.area());
            }
        }
        assert_eq!(
            Rle::encode_cropped(&CroppedMask::empty(5, 3)),
            Rle::encode(&Mask::new(3, 5))
        );
    }

    #[test]
    fn encode_is_column_major_and_decodes_back() {
        let m = mask(3, 4, &[(1, 0), (1, 1), (3, 2), (0, 2)]);
        let rle = Rle::encode(&m);
        // column 0: 0 0 1 | column 1: 1 1 0 | column 2: 0 0 0 | column 3: 0 0 1
        assert_eq!(rle.counts, vec![2, 3, 6, 1]);
        assert_eq!(rle.decode(), m);
        assert_eq!(rle.area(), 4);
        assert_eq!(rle.bbox(), [0.0, 0.0, 4.0, 3.0]);
    }

    #[test]
    fn empty_and_full_masks() {
        let empty = Rle::encode(&Mask::new(5, 7));
        assert_eq!(empty.counts, vec![35]);
        assert_eq!(empty.bbox(), [0.0; 4]);
        assert_eq!(empty.area(), 0);
        let full = Mask::from_row_major(2, 2, vec![1; 4]).unwrap();
        let rle = Rle::encode(&full);
        assert_eq!(rle.counts, vec![0, 4]);
        assert_eq!(rle.to_compressed(), "04");
        assert_eq!(rle.bbox(), [0.0, 0.0, 2.0, 2.0]);
    }

    #[test]
    fn large_and_negative_deltas_round_trip() {
        let rle = Rle {
            height: 1000,
            width: 1000,
            counts: vec![123_456, 70_000, 3, 500_000, 306_541],
        };
        let s = rle.to_compressed();
        assert_eq!(Rle::from_compressed(&s, 1000, 1000).unwrap(), rle);
    }

    #[test]
    fn bad_strings_are_errors_not_panics() {
        assert_eq!(
            Rle::from_compressed("5 2", 4, 4),
            Err(RleError::BadChar(' '))
        );
        assert_eq!(Rle::from_compressed("P", 4, 4), Err(RleError::Truncated));
        assert!(matches!(
            Rle::from_compressed("52203", 5, 5),
            Err(RleError::WrongTotal { sum: 16, .. })
        ));
    }

    #[test]
    fn merge_and_iou_agree_with_pixels() {
        let a = mask(6, 6, &[(0, 0), (1, 1), (2, 2), (3, 3)]);
        let b = mask(6, 6, &[(1, 1), (2, 2), (5, 5)]);
        let (ra, rb) = (Rle::encode(&a), Rle::encode(&b));
        let union = Rle::merge(&[ra.clone(), rb.clone()], false);
        let inter = Rle::merge(&[ra.clone(), rb.clone()], true);
        assert_eq!(union.area(), 5);
        assert_eq!(inter.area(), 2);
        let iou = rle_iou(&ra, &ra.bbox(), &rb, &rb.bbox(), false);
        assert_eq!(iou, a.iou(&b));
        // crowd: intersection over the detection's own area
        let crowd = rle_iou(&ra, &ra.bbox(), &rb, &rb.bbox(), true);
        assert_eq!(crowd, 2.0 / 4.0);
    }

    #[test]
    fn bbox_iou_matches_hand_values() {
        let d = [0.0, 0.0, 10.0, 10.0];
        let g = [5.0, 5.0, 10.0, 10.0];
        assert_eq!(bbox_iou(&d, &g, false), 25.0 / 175.0);
        assert_eq!(bbox_iou(&d, &g, true), 25.0 / 100.0);
        assert_eq!(bbox_iou(&d, &[10.0, 0.0, 5.0, 5.0], false), 0.0);
    }
}
