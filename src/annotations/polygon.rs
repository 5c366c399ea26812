//! Polygons ↔ masks.
//!
//! `rle_from_polygon` is a port of pycocotools' `rleFrPoly` (upsample ×5, walk the edges,
//! keep the y-boundary crossings at pixel centres), because GT polygons must rasterise to
//! exactly the pixels pycocotools evaluates against. `mask_to_polygons` goes the other
//! way for labels made from masks (renderer, predictions): it follows pixel edges, so the
//! outline re-rasterises to the same pixels (holes are filled: COCO polygons have none).

use super::mask::Mask;
use super::rle::Rle;

/// C's `(int)` cast of a double as x86 performs it: truncation toward zero, and
/// `INT_MIN` for NaN or out-of-range values.
#[inline]
fn c_int(v: f64) -> i32 {
    if v.is_nan() || v >= 2147483648.0 || v <= -2147483649.0 {
        i32::MIN
    } else {
        v as i32
    }
}

/// `rleFrPoly` for one flat polygon `[x0, y0, x1, y1, ...]` (an odd trailing coordinate
/// is dropped, as pycocotools' `len(p)/2` does).
pub fn rle_from_polygon(xy: &[f64], height: u32, width: u32) -> Rle {
    let k = xy.len() / 2;
    let (h, w) = (height as i64, width as i64);
    let scale = 5.0f64;
    if k == 0 {
        return Rle {
            height,
            width,
            counts: vec![(h * w) as u32],
        };
    }
    let mut x: Vec<i32> = (0..k).map(|j| c_int(scale * xy[j * 2] + 0.5)).collect();
    let mut y: Vec<i32> = (0..k).map(|j| c_int(scale * xy[j * 2 + 1] + 0.5)).collect();
    x.push(x[0]);
    y.push(y[0]);
    // Dense boundary points of the upsampled polygon.
    let mut u: Vec<i32> = Vec::new();
    let mut v: Vec<i32> = Vec::new();
    for j in 0..k {
        let (mut xs, mut xe, mut ys, mut ye) = (x[j], x[j + 1], y[j], y[j + 1]);
        let dx = xe.wrapping_sub(xs).wrapping_abs();
        let dy = ys.wrapping_sub(ye).wrapping_abs();
        let flip = (dx >= dy && xs > xe) || (dx < dy && ys > ye);
        if flip {
            std::mem::swap(&mut xs, &mut xe);
            std::mem::swap(&mut ys, &mut ye);
        }
        let s = if dx >= dy {
            (ye.wrapping_sub(ys)) as f64 / dx as f64
        } else {
            (xe.wrapping_sub(xs)) as f64 / dy as f64
        };
        if dx >= dy {
            for d in 0..=dx {
                let t = if flip { dx - d } else { d };
                u.push(t.wrapping_add(xs));
                v.push(c_int(ys as f64 + s * t as f64 + 0.5));
            }
        } else {
            for d in 0..=dy {
                let t = if flip { dy - d } else { d };
                v.push(t.wrapping_add(ys));
                u.push(c_int(xs as f64 + s * t as f64 + 0.5));
            }
        }
    }
    // Points on the y-boundary, downsampled back to pixel centres.
    let mut bx: Vec<i32> = Vec::new();
    let mut by: Vec<i32> = Vec::new();
    for j in 1..u.len() {
        if u[j] == u[j - 1] {
            continue;
        }
        let mut xd = (if u[j] < u[j - 1] { u[j] } else { u[j] - 1 }) as f64;
        xd = (xd + 0.5) / scale - 0.5;
        if xd.floor() != xd || xd < 0.0 || xd > (w - 1) as f64 {
            continue;
        }
        let mut yd = (if v[j] < v[j - 1] { v[j] } else { v[j - 1] }) as f64;
        yd = (yd + 0.5) / scale - 0.5;
        if yd < 0.0 {
            yd = 0.0;
        } else if yd > h as f64 {
            yd = h as f64;
        }
        yd = yd.ceil();
        bx.push(xd as i32);
        by.push(yd as i32);
    }
    Rle {
        height,
        width,
        counts: runs_from_boundary(&bx, &by, h, w),
    }
}

/// `rleFrPoly`'s last step: run lengths (column-major) from the boundary points where the
/// mask switches, the sorted positions differenced and zero-length runs merged.
fn runs_from_boundary(bx: &[i32], by: &[i32], h: i64, w: i64) -> Vec<u32> {
    let mut a: Vec<u32> = bx
        .iter()
        .zip(by)
        .map(|(&px, &py)| px.wrapping_mul(h as i32).wrapping_add(py) as u32)
        .collect();
    a.push((h * w) as u32);
    a.sort_unstable();
    let mut p = 0u32;
    for aj in a.iter_mut() {
        let t = *aj;
        *aj = aj.wrapping_sub(p);
        p = t;
    }
    let mut b: Vec<u32> = Vec::with_capacity(a.len());
    let mut j = 0;
    b.push(a[j]);
    j += 1;
    while j < a.len() {
        if a[j] > 0 {
            b.push(a[j]);
            j += 1;
        } else {
            j += 1;
            if j < a.len() {
                let last = b.len() - 1;
                b[last] = b[last].wrapping_add(a[j]);
                j += 1;
            }
        }
    }
    b
}

/// `rleFrBbox`: the mask of an [x, y, w, h] box, through the polygon rasteriser (here,
/// not on [`Rle`], so that `rle` stays below `polygon`).
pub fn rle_from_bbox(bbox: [f64; 4], height: u32, width: u32) -> Rle {
    let (xs, ys) = (bbox[0], bbox[1]);
    let (xe, ye) = (xs + bbox[2], ys + bbox[3]);
    rle_from_polygon(&[xs, ys, xs, ye, xe, ye, xe, ys], height, width)
}

/// The union of several polygons of one instance, as `frPyObjects` + `merge` build it.
pub fn rle_from_polygons(polys: &[Vec<f64>], height: u32, width: u32) -> Rle {
    let rles: Vec<Rle> = polys
        .iter()
        .map(|p| rle_from_polygon(p, height, width))
        .collect();
    Rle::merge(&rles, false)
}

/// Outer outlines of the 4-connected parts of a mask, as flat `[x0, y0, x1, y1, ...]`
/// polygons through pixel corners (largest part first). Each has at least 4 vertices.
pub fn mask_to_polygons(mask: &Mask) -> Vec<Vec<f64>> {
    let (w, h) = (mask.width as i64, mask.height as i64);
    let labels = label_components(mask);
    let inside = |label: u32, px: i64, py: i64| -> bool {
        px >= 0 && py >= 0 && px < w && py < h && labels[(py * w + px) as usize] == label
    };
    let parts = labels.iter().copied().max().unwrap_or(0) as usize;
    let mut seen = vec![false; parts + 1];
    let mut polys: Vec<(u64, Vec<f64>)> = Vec::new();
    let mut sizes: std::collections::HashMap<u32, u64> = std::collections::HashMap::new();
    for &l in &labels {
        if l != 0 {
            *sizes.entry(l).or_default() += 1;
        }
    }
    for py in 0..h {
        for px in 0..w {
            let label = labels[(py * w + px) as usize];
            if label == 0 || seen[label as usize] {
                continue;
            }
            seen[label as usize] = true;
            // The first pixel met in raster order has its top edge on the outer outline.
            // Walk clockwise (y down) with the part on the right-hand side.
            const DIRS: [(i64, i64); 4] = [(1, 0), (0, 1), (-1, 0), (0, -1)];
            let (sx, sy) = (px, py);
            let (mut cx, mut cy, mut d) = (px + 1, py, 0usize);
            let mut verts: Vec<f64> = vec![sx as f64, sy as f64];
            loop {
                // Pixels ahead-left and ahead-right of the corner, for each direction.
                let (al, ar) = match d {
                    0 => ((cx, cy - 1), (cx, cy)),
                    1 => ((cx, cy), (cx - 1, cy)),
                    2 => ((cx - 1, cy), (cx - 1, cy - 1)),
                    _ => ((cx - 1, cy - 1), (cx, cy - 1)),
                };
                let l_in = inside(label, al.0, al.1);
                let r_in = inside(label, ar.0, ar.1);
                let nd = if l_in && r_in {
                    (d + 3) % 4
                } else if r_in {
                    d
                } else {
                    (d + 1) % 4
                };
                if nd != d {
                    verts.push(cx as f64);
                    verts.push(cy as f64);
                }
                d = nd;
                if cx == sx && cy == sy {
                    break;
                }
                cx += DIRS[d].0;
                cy += DIRS[d].1;
            }
            // The start corner was pushed twice (first and as the final turn).
            verts.truncate(verts.len() - 2);
            polys.push((sizes[&label], verts));
        }
    }
    polys.sort_by(|a, b| b.0.cmp(&a.0));
    polys.into_iter().map(|(_, p)| p).collect()
}

/// 4-connected component labels (0 = background, 1.. = parts), by flood fill.
fn label_components(mask: &Mask) -> Vec<u32> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut labels = vec![0u32; w * h];
    let mut next = 0u32;
    let mut stack = Vec::new();
    for start in 0..w * h {
        if mask.data[start] == 0 || labels[start] != 0 {
            continue;
        }
        next += 1;
        labels[start] = next;
        stack.push(start);
        while let Some(p) = stack.pop() {
            let (x, y) = (p % w, p / w);
            let mut visit = |q: usize| {
                if mask.data[q] != 0 && labels[q] == 0 {
                    labels[q] = next;
                    stack.push(q);
                }
            };
            if x > 0 {
                visit(p - 1);
            }
            if x + 1 < w {
                visit(p + 1);
            }
            if y > 0 {
                visit(p - w);
            }
            if y + 1 < h {
                visit(p + w);
            }
        }
    }
    labels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_polygon_matches_pycocotools() {
        // pycocotools: frPyObjects([[1,1,4,1,4,3,1,3]], 5, 6) -> counts [6,2,3,2,3,2,12]
        let rle = rle_from_polygon(&[1.0, 1.0, 4.0, 1.0, 4.0, 3.0, 1.0, 3.0], 5, 6);
        assert_eq!(rle.area(), 6);
        assert_eq!(rle.counts, vec![6, 2, 3, 2, 3, 2, 12]);
    }

    #[test]
    fn traced_outlines_rasterise_to_the_same_pixels() {
        let mut m = Mask::new(20, 24);
        for y in 0..20u32 {
            for x in 0..24u32 {
                let (dx, dy) = (x as f64 - 8.0, y as f64 - 9.0);
                let blob = dx * dx / 30.0 + dy * dy / 50.0 < 1.0;
                let bar = (17..22).contains(&x) && (2..15).contains(&y);
                m.set(x, y, blob || bar);
            }
        }
        m.set(0, 19, true); // a one-pixel part in the corner
        let polys = mask_to_polygons(&m);
        assert_eq!(polys.len(), 3);
        assert!(polys.iter().all(|p| p.len() >= 8));
        let back = rle_from_polygons(&polys, 20, 24).decode();
        assert_eq!(back, m);
    }

    #[test]
    fn diagonal_neighbours_are_separate_parts() {
        let mut m = Mask::new(4, 4);
        m.set(1, 1, true);
        m.set(2, 2, true);
        let polys = mask_to_polygons(&m);
        assert_eq!(polys.len(), 2);
        assert_eq!(rle_from_polygons(&polys, 4, 4).decode(), m);
    }
}
