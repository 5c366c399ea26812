//! Test-time augmentation for top views: the model sees an image in each of the eight
//! symmetries of the square (four quarter turns, each also mirrored), every view's
//! detections are mapped back to the image, and the detections of one instance across
//! views are fused into one.
//!
//! Why these views: a pile seen from above has no up and no handedness, so every
//! symmetry of the square shows a valid image of the same pile (the trainer draws
//! rotations by any angle and both flips for that reason). ultralytics' `augment=True`
//! uses scales and left-right flips for detection and none for segmentation; detectron2's
//! `GeneralizedRCNNWithTTA` uses scales and flips and merges boxes with NMS. Here every
//! view keeps its own mask, so the fusion votes on masks, not only on boxes: a
//! cluster of detections (one per view at most, mask IoU above a threshold, greedy by
//! score as in NMS) becomes one detection whose mask is the score-weighted majority of
//! its members' masks, whose box is their score-weighted mean (weighted box fusion) and
//! whose score is the members' sum over the number of views, so an instance found in
//! every view outranks one found in a few.

use image::RgbImage;

use crate::annotations::mask::{CroppedMask, Mask};

/// One symmetry of the square: `turns` quarter turns clockwise, then, when `mirror`, a
/// left-right mirror of the turned image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct View {
    pub turns: u8,
    pub mirror: bool,
}

impl View {
    /// The eight views, the image as it is first.
    pub const ALL: [View; 8] = [
        View::new(0, false),
        View::new(1, false),
        View::new(2, false),
        View::new(3, false),
        View::new(0, true),
        View::new(1, true),
        View::new(2, true),
        View::new(3, true),
    ];

    pub const fn new(turns: u8, mirror: bool) -> View {
        View {
            turns: turns % 4,
            mirror,
        }
    }

    /// The image as this view shows it.
    pub fn image(&self, img: &RgbImage) -> RgbImage {
        let mut out = match self.turns {
            0 => img.clone(),
            1 => image::imageops::rotate90(img),
            2 => image::imageops::rotate180(img),
            _ => image::imageops::rotate270(img),
        };
        if self.mirror {
            image::imageops::flip_horizontal_in_place(&mut out);
        }
        out
    }

    /// `(width, height)` of the view of a `(width, height)` image (and of the image of a
    /// view: odd turns swap the sides either way).
    pub fn size(&self, (w, h): (u32, u32)) -> (u32, u32) {
        if self.turns % 2 == 1 {
            (h, w)
        } else {
            (w, h)
        }
    }

    /// The point `(u, v)` of a view of size `viewed` (continuous coordinates, pixel `x`
    /// spans `[x, x + 1)`) in the original image: the mirror undone, then the turns.
    fn unmap_point(&self, (mut u, mut v): (f64, f64), viewed: (u32, u32)) -> (f64, f64) {
        let (mut w, mut h) = (viewed.0 as f64, viewed.1 as f64);
        if self.mirror {
            u = w - u;
        }
        for _ in 0..self.turns {
            // One clockwise turn takes (x, y) of a W × H image to (H − y, x) of an H × W
            // one; undone, (u, v) of the w × h view comes from (v, w − u) of an h × w image.
            (u, v) = (v, w - u);
            (w, h) = (h, w);
        }
        (u, v)
    }

    /// The pixel `(x, y)` of a view of size `viewed` in the original image.
    fn unmap_pixel(&self, (x, y): (u32, u32), viewed: (u32, u32)) -> (u32, u32) {
        let (u, v) = self.unmap_point((x as f64 + 0.5, y as f64 + 0.5), viewed);
        (u.floor() as u32, v.floor() as u32)
    }

    /// An xyxy box of a view of size `viewed` in the original image.
    pub fn unmap_box(&self, b: [f64; 4], viewed: (u32, u32)) -> [f64; 4] {
        let (a0, a1) = self.unmap_point((b[0], b[1]), viewed);
        let (c0, c1) = self.unmap_point((b[2], b[3]), viewed);
        [a0.min(c0), a1.min(c1), a0.max(c0), a1.max(c1)]
    }

    /// A mask of a view in the original image (a pixel permutation: nothing is resampled).
    pub fn unmap_mask(&self, m: &CroppedMask) -> CroppedMask {
        let viewed = (m.width, m.height);
        let (w, h) = self.size(viewed);
        let (ww, wh) = (m.window.width, m.window.height);
        if ww == 0 || wh == 0 {
            return CroppedMask::empty(w, h);
        }
        let a = self.unmap_pixel((m.x0, m.y0), viewed);
        let b = self.unmap_pixel((m.x0 + ww - 1, m.y0 + wh - 1), viewed);
        let (x0, y0) = (a.0.min(b.0), a.1.min(b.1));
        let (nw, nh) = (a.0.max(b.0) - x0 + 1, a.1.max(b.1) - y0 + 1);
        let mut window = Mask::new(nh, nw);
        for y in 0..wh {
            for x in 0..ww {
                if m.window.get(x, y) {
                    let (ox, oy) = self.unmap_pixel((m.x0 + x, m.y0 + y), viewed);
                    window.set(ox - x0, oy - y0, true);
                }
            }
        }
        CroppedMask {
            width: w,
            height: h,
            x0,
            y0,
            window,
        }
    }
}

/// A detection of one view, mapped back to the original image.
#[derive(Clone, Debug)]
pub struct ViewDetection {
    /// Index of the view it came from (at most one member per view in a fused detection).
    pub view: usize,
    pub class: usize,
    pub score: f32,
    /// xyxy in original-image pixels.
    pub xyxy: [f64; 4],
    pub mask: CroppedMask,
}

/// Detections of several views fused into one per instance.
#[derive(Clone, Debug, PartialEq)]
pub struct Fused {
    pub class: usize,
    /// Sum of the members' scores over the number of views.
    pub score: f32,
    pub xyxy: [f64; 4],
    pub mask: CroppedMask,
    /// How many views found it.
    pub members: usize,
}

/// Mask IoU of two cropped masks of the same image (0 when both are empty).
pub fn cropped_iou(a: &CroppedMask, b: &CroppedMask) -> f64 {
    iou_with_areas(a, a.area(), b, b.area())
}

/// [`cropped_iou`] with the two areas known: windows that do not overlap cost nothing
/// (most pairs in a fusion of hundreds of detections).
fn iou_with_areas(a: &CroppedMask, aa: u64, b: &CroppedMask, ba: u64) -> f64 {
    let x0 = a.x0.max(b.x0);
    let y0 = a.y0.max(b.y0);
    let x1 = (a.x0 + a.window.width).min(b.x0 + b.window.width);
    let y1 = (a.y0 + a.window.height).min(b.y0 + b.window.height);
    if x0 >= x1 || y0 >= y1 {
        return 0.0;
    }
    let mut inter = 0u64;
    for y in y0..y1 {
        let ra = ((y - a.y0) * a.window.width) as usize;
        let rb = ((y - b.y0) * b.window.width) as usize;
        for x in x0..x1 {
            let pa = a.window.data[ra + (x - a.x0) as usize] != 0;
            let pb = b.window.data[rb + (x - b.x0) as usize] != 0;
            inter += (pa && pb) as u64;
        }
    }
    let union = aa + ba - inter;
    if union == 0 {
        0.0
    } else {
        inter as f64 / union as f64
    }
}

/// Fuses the detections of `views` views (see the module doc): greedy by descending
/// score, each detection joins the cluster of its class whose first (best) member its
/// mask overlaps most at IoU > `iou`, if that cluster has no member of its view yet, else
/// starts one. Returns at most `max_det` fused detections of each class, by descending
/// score. NaN scores are dropped.
pub fn fuse(dets: &[ViewDetection], views: usize, iou: f64, max_det: usize) -> Vec<Fused> {
    let mut order: Vec<usize> = (0..dets.len())
        .filter(|&i| !dets[i].score.is_nan())
        .collect();
    order.sort_by(|&i, &j| dets[j].score.total_cmp(&dets[i].score).then(i.cmp(&j)));
    let areas: Vec<u64> = dets.iter().map(|d| d.mask.area()).collect();
    // (members, views seen as a bit set)
    let mut clusters: Vec<(Vec<usize>, u64)> = Vec::new();
    for &i in &order {
        let d = &dets[i];
        let bit = 1u64 << (d.view % 64);
        let mut best: Option<(f64, usize)> = None;
        for (c, (members, seen)) in clusters.iter().enumerate() {
            let rep = &dets[members[0]];
            if rep.class != d.class || seen & bit != 0 {
                continue;
            }
            let v = iou_with_areas(&rep.mask, areas[members[0]], &d.mask, areas[i]);
            if v > iou && best.is_none_or(|(b, _)| v > b) {
                best = Some((v, c));
            }
        }
        match best {
            Some((_, c)) => {
                clusters[c].0.push(i);
                clusters[c].1 |= bit;
            }
            None => clusters.push((vec![i], bit)),
        }
    }
    let views = views.max(1) as f32;
    let mut scored: Vec<(f32, usize)> = clusters
        .iter()
        .enumerate()
        .map(|(c, (m, _))| (m.iter().map(|&i| dets[i].score).sum::<f32>() / views, c))
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut per_class = std::collections::HashMap::new();
    scored.retain(|&(_, c)| {
        let n = per_class
            .entry(dets[clusters[c].0[0]].class)
            .or_insert(0usize);
        *n += 1;
        *n <= max_det
    });
    scored
        .into_iter()
        .map(|(score, c)| {
            let members: Vec<&ViewDetection> = clusters[c].0.iter().map(|&i| &dets[i]).collect();
            merge(&members, score)
        })
        .collect()
}

/// One fused detection of `members` (non-empty, best first): box the score-weighted mean,
/// mask the pixels covered by members holding at least half of the members' total score.
fn merge(members: &[&ViewDetection], score: f32) -> Fused {
    let first = members[0];
    let weights: Vec<f64> = members.iter().map(|d| d.score.max(0.0) as f64).collect();
    let total: f64 = weights.iter().sum();
    // All-zero scores: an unweighted vote.
    let weights: Vec<f64> = if total > 0.0 {
        weights
    } else {
        vec![1.0; members.len()]
    };
    let total: f64 = weights.iter().sum();
    let mut xyxy = [0.0; 4];
    for (d, w) in members.iter().zip(&weights) {
        for k in 0..4 {
            xyxy[k] += w * d.xyxy[k] / total;
        }
    }
    let (width, height) = (first.mask.width, first.mask.height);
    let nonempty: Vec<(&CroppedMask, f64)> = members
        .iter()
        .zip(&weights)
        .filter(|(d, _)| d.mask.window.width > 0 && d.mask.window.height > 0)
        .map(|(d, &w)| (&d.mask, w))
        .collect();
    let mask = if nonempty.is_empty() {
        CroppedMask::empty(width, height)
    } else {
        let x0 = nonempty.iter().map(|(m, _)| m.x0).min().unwrap_or(0);
        let y0 = nonempty.iter().map(|(m, _)| m.y0).min().unwrap_or(0);
        let x1 = nonempty
            .iter()
            .map(|(m, _)| m.x0 + m.window.width)
            .max()
            .unwrap_or(0);
        let y1 = nonempty
            .iter()
            .map(|(m, _)| m.y0 + m.window.height)
            .max()
            .unwrap_or(0);
        let (ww, wh) = (x1 - x0, y1 - y0);
        let mut votes = vec![0.0f64; (ww * wh) as usize];
        for (m, w) in &nonempty {
            for y in 0..m.window.height {
                for x in 0..m.window.width {
                    if m.window.get(x, y) {
                        votes[((m.y0 + y - y0) * ww + (m.x0 + x - x0)) as usize] += w;
                    }
                }
            }
        }
        let data = votes.iter().map(|&v| (v >= 0.5 * total) as u8).collect();
        CroppedMask {
            width,
            height,
            x0,
            y0,
            window: Mask::from_row_major(wh, ww, data).expect("window size matches its data"),
        }
    };
    Fused {
        class: first.class,
        score,
        xyxy,
        mask,
        members: members.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    /// A `w × h` image whose every pixel is different.
    fn numbered(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| Rgb([x as u8, y as u8, (x * 7 + y * 13) as u8]))
    }

    fn cropped(w: u32, h: u32, pixels: &[(u32, u32)]) -> CroppedMask {
        let mut full = Mask::new(h, w);
        for &(x, y) in pixels {
            full.set(x, y, true);
        }
        let x0 = pixels.iter().map(|p| p.0).min().unwrap();
        let y0 = pixels.iter().map(|p| p.1).min().unwrap();
        let x1 = pixels.iter().map(|p| p.0).max().unwrap() + 1;
        let y1 = pixels.iter().map(|p| p.1).max().unwrap() + 1;
        let mut window = Mask::new(y1 - y0, x1 - x0);
        for &(x, y) in pixels {
            window.set(x - x0, y - y0, true);
        }
        CroppedMask {
            width: w,
            height: h,
            x0,
            y0,
            window,
        }
    }

    #[test]
    fn every_view_pixel_maps_back_to_the_pixel_it_shows() {
        let img = numbered(7, 4);
        for v in View::ALL {
            let seen = v.image(&img);
            assert_eq!(seen.dimensions(), v.size((7, 4)), "{v:?}");
            for (x, y, p) in seen.enumerate_pixels() {
                let (ox, oy) = v.unmap_pixel((x, y), seen.dimensions());
                assert_eq!(img.get_pixel(ox, oy), p, "{v:?} at ({x}, {y})");
            }
        }
    }

    #[test]
    fn the_eight_views_are_distinct() {
        let img = numbered(5, 5);
        let seen: Vec<RgbImage> = View::ALL.iter().map(|v| v.image(&img)).collect();
        for i in 0..8 {
            for j in i + 1..8 {
                assert_ne!(
                    seen[i],
                    seen[j],
                    "{:?} and {:?}",
                    View::ALL[i],
                    View::ALL[j]
                );
            }
        }
    }

    #[test]
    fn masks_and_boxes_map_back_with_the_image() {
        // An L-shaped instance in a 9 × 6 image, drawn into each view through the image
        // transform; mapped back it must be the same pixels and the same box.
        let (w, h) = (9, 6);
        let pixels = [(2, 1), (2, 2), (2, 3), (3, 3), (4, 3), (5, 3)];
        let orig = cropped(w, h, &pixels);
        let box_orig = [2.0, 1.0, 6.0, 4.0];
        for v in View::ALL {
            let mut canvas = RgbImage::new(w, h);
            for &(x, y) in &pixels {
                canvas.put_pixel(x, y, Rgb([255, 255, 255]));
            }
            let seen = v.image(&canvas);
            let on: Vec<(u32, u32)> = seen
                .enumerate_pixels()
                .filter(|p| p.2 .0[0] == 255)
                .map(|p| (p.0, p.1))
                .collect();
            let in_view = cropped(seen.width(), seen.height(), &on);
            assert_eq!(v.unmap_mask(&in_view).full(), orig.full(), "{v:?}");
            let x0 = on.iter().map(|p| p.0).min().unwrap() as f64;
            let y0 = on.iter().map(|p| p.1).min().unwrap() as f64;
            let x1 = on.iter().map(|p| p.0).max().unwrap() as f64 + 1.0;
            let y1 = on.iter().map(|p| p.1).max().unwrap() as f64 + 1.0;
            assert_eq!(
                v.unmap_box([x0, y0, x1, y1], seen.dimensions()),
                box_orig,
                "{v:?}"
            );
        }
        let empty = CroppedMask::empty(6, 9);
        assert_eq!(
            View::new(1, false).unmap_mask(&empty).full(),
            Mask::new(6, 9)
        );
    }

    fn det(view: usize, score: f32, pixels: &[(u32, u32)]) -> ViewDetection {
        let mask = cropped(10, 10, pixels);
        let xyxy = [
            mask.x0 as f64,
            mask.y0 as f64,
            (mask.x0 + mask.window.width) as f64,
            (mask.y0 + mask.window.height) as f64,
        ];
        ViewDetection {
            view,
            class: 0,
            score,
            xyxy,
            mask,
        }
    }

    fn square(x0: u32, y0: u32, s: u32) -> Vec<(u32, u32)> {
        (y0..y0 + s)
            .flat_map(|y| (x0..x0 + s).map(move |x| (x, y)))
            .collect()
    }

    #[test]
    fn one_instance_across_views_fuses_into_one_by_weighted_vote() {
        // Three views see the same 4 × 4 square; one of them (the lowest score) sees it
        // one pixel wider. A fourth view sees something else.
        let mut wide = square(1, 1, 4);
        wide.extend((1..5).map(|y| (5, y)));
        let dets = vec![
            det(0, 0.9, &square(1, 1, 4)),
            det(1, 0.8, &square(1, 1, 4)),
            det(2, 0.3, &wide),
            det(3, 0.6, &square(7, 7, 2)),
        ];
        let fused = fuse(&dets, 4, 0.5, 100);
        assert_eq!(fused.len(), 2);
        assert_eq!(fused[0].members, 3);
        assert!((fused[0].score - 2.0 / 4.0).abs() < 1e-6);
        // The wider column holds 0.3 of 2.0: outvoted.
        assert_eq!(
            fused[0].mask.full(),
            cropped(10, 10, &square(1, 1, 4)).full()
        );
        let expected_x1 = (0.9 * 5.0 + 0.8 * 5.0 + 0.3 * 6.0) / 2.0;
        // (The scores are f32: 1e-6, not 1e-12.)
        assert!((fused[0].xyxy[2] - expected_x1).abs() < 1e-6);
        assert_eq!(fused[1].members, 1);
        assert!((fused[1].score - 0.15).abs() < 1e-6);
    }

    #[test]
    fn a_view_adds_one_member_per_cluster_and_classes_stay_apart() {
        // Two detections of the same view on the same square are two instances (NMS
        // kept both), and a detection of another class never joins.
        let mut other = det(1, 0.7, &square(1, 1, 4));
        other.class = 1;
        let dets = vec![
            det(0, 0.9, &square(1, 1, 4)),
            det(0, 0.5, &square(1, 1, 4)),
            other,
            det(1, f32::NAN, &square(1, 1, 4)),
        ];
        let fused = fuse(&dets, 2, 0.5, 100);
        assert_eq!(fused.len(), 3);
        assert!(fused.iter().all(|f| f.members == 1));
        // At most one per class: the best of class 0 and the one of class 1.
        let one = fuse(&dets, 2, 0.5, 1);
        assert_eq!(one.len(), 2);
        assert_eq!((one[0].class, one[0].score), (0, 0.45));
        assert_eq!(one[1].class, 1);
    }

    #[test]
    fn cropped_iou_counts_pixels() {
        let a = cropped(10, 10, &square(0, 0, 4));
        let b = cropped(10, 10, &square(2, 2, 4));
        assert!((cropped_iou(&a, &b) - 4.0 / 28.0).abs() < 1e-12);
        assert_eq!(cropped_iou(&a, &cropped(10, 10, &square(6, 6, 2))), 0.0);
        let e = CroppedMask::empty(10, 10);
        assert_eq!(cropped_iou(&e, &e), 0.0);
    }
}
