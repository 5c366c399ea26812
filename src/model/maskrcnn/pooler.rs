//! Multi-level RoI pooling (detectron2 `modeling/poolers.py`): each RoI is pooled from the
//! one FPN level its size selects, `level = ⌊4 + log2(√(wh) / 224)⌋` clamped to the pooled
//! levels (FPN paper eq. 1, canonical box 224 px on level 4), then [`roi_align`].

use burn::tensor::Tensor;

use super::roi_align::{index_tensor, roi_align};

/// Canonical box size (px) that maps to [`CANONICAL_LEVEL`].
pub const CANONICAL_BOX: f32 = 224.0;
pub const CANONICAL_LEVEL: f32 = 4.0;

/// FPN level of an xyxy box, clamped to `[min_level, max_level]`.
pub fn assign_level(b: [f32; 4], min_level: usize, max_level: usize) -> usize {
    let area = ((b[2] - b[0]) * (b[3] - b[1])).max(0.0);
    let l = (CANONICAL_LEVEL + (area.sqrt() / CANONICAL_BOX + 1e-8).log2()).floor();
    (l.max(min_level as f32).min(max_level as f32)) as usize
}

/// Pools `rois` from `features` (levels `min_level ..`, finest first, level `l` has stride
/// `2^l`) with RoIAlign of `output × output`, `sampling` samples per bin side.
///
/// # Shapes
/// - `features[i]`: `[B, C, H / 2^(min_level+i), W / 2^(min_level+i)]`
/// - returns `[N, C, output, output]`, rows in the order of `rois`
pub fn pool_levels(
    features: &[Tensor<4>],
    min_level: usize,
    rois: &[(usize, [f32; 4])],
    output: usize,
    sampling: usize,
) -> Tensor<4> {
    assert!(!features.is_empty(), "pool_levels: no feature levels");
    let max_level = min_level + features.len() - 1;
    let mut groups: Vec<Vec<usize>> = vec![Vec::new(); features.len()];
    for (i, r) in rois.iter().enumerate() {
        groups[assign_level(r.1, min_level, max_level) - min_level].push(i);
    }
    let mut parts = Vec::new();
    let mut order = Vec::with_capacity(rois.len());
    for (l, g) in groups.iter().enumerate() {
        if g.is_empty() {
            continue;
        }
        let sub: Vec<(usize, [f32; 4])> = g.iter().map(|&i| rois[i]).collect();
        let scale = 1.0 / (1usize << (min_level + l)) as f32;
        parts.push(roi_align(
            features[l].clone(),
            &sub,
            scale,
            [output, output],
            sampling,
        ));
        order.extend_from_slice(g);
    }
    if parts.is_empty() {
        let [_, c, _, _] = features[0].dims();
        return Tensor::zeros([0, c, output, output], &features[0].device());
    }
    let pooled = Tensor::cat(parts, 0);
    if order.iter().enumerate().all(|(i, &o)| i == o) {
        return pooled;
    }
    // pooled row r holds RoI order[r]; invert.
    let mut inv = vec![0usize; order.len()];
    for (r, &o) in order.iter().enumerate() {
        inv[o] = r;
    }
    pooled.select(0, index_tensor(&inv, &features[0].device()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Device;

    #[test]
    fn level_hand_values() {
        let sq = |s: f32| [0.0, 0.0, s, s];
        assert_eq!(assign_level(sq(224.0), 2, 5), 4);
        assert_eq!(assign_level(sq(223.0), 2, 5), 3);
        assert_eq!(assign_level(sq(112.0), 2, 5), 3);
        assert_eq!(assign_level(sq(111.0), 2, 5), 2);
        assert_eq!(assign_level(sq(448.0), 2, 5), 5);
        assert_eq!(assign_level(sq(10.0), 2, 5), 2);
        assert_eq!(assign_level(sq(5000.0), 2, 5), 5);
        assert_eq!(assign_level([0.0, 0.0, 0.0, 0.0], 2, 5), 2);
    }

    #[test]
    fn rois_come_back_in_order() {
        let d = Device::flex();
        // Level 2 is all ones, level 3 all twos: a small RoI must read 1, a large one 2.
        let p2: Tensor<4> = Tensor::ones([1, 1, 64, 64], &d);
        let p3: Tensor<4> = Tensor::ones([1, 1, 32, 32], &d) * 2.0;
        let rois = [
            (0, [100.0, 100.0, 220.0, 220.0]),
            (0, [10.0, 10.0, 30.0, 30.0]),
            (0, [0.0, 0.0, 130.0, 120.0]),
        ];
        let out = pool_levels(&[p2, p3], 2, &rois, 2, 1);
        assert_eq!(out.dims(), [3, 1, 2, 2]);
        let v = out.into_data_as::<f32>().try_into_vec::<f32>().unwrap();
        let want = [2.0f32, 2., 2., 2., 1., 1., 1., 1., 2., 2., 2., 2.];
        assert_eq!(v, want);
    }
}
