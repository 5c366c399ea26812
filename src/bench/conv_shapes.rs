//! The convolutions of the models `chicktrain bench convs` times (issue 37): YOLO11n-seg
//! and the compact Mask R-CNN R18, each as a list of distinct shapes with how many layers
//! of the model have that shape at a given input size. Written out from the model code
//! (`crate::model::yolo`, `crate::model::maskrcnn`) rather than traced from a built model,
//! so the bench needs no model; `tests` pins the layer counts, and the ResNet-18 trunk's
//! multiply-adds against `ResNet::macs`.

/// One convolution: `c_in → c_out`, `k×k`, stride, groups (padding `k / 2`), input
/// `hw × hw`, and how many layers of the model have exactly this shape (`name` lists
/// every layer group merged into the row, joined by " + ").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConvShape {
    pub model: &'static str,
    pub name: String,
    pub c_in: usize,
    pub c_out: usize,
    pub k: usize,
    pub stride: usize,
    pub groups: usize,
    pub hw: usize,
    pub count: usize,
}

impl ConvShape {
    /// Output side length (padding `k / 2`, dilation 1).
    pub fn out_hw(&self) -> usize {
        (self.hw + 2 * (self.k / 2) - self.k) / self.stride + 1
    }

    /// Multiply-adds of one image through one layer of this shape.
    pub fn macs(&self) -> u64 {
        let o = self.out_hw() as u64;
        o * o * (self.c_out * (self.c_in / self.groups) * self.k * self.k) as u64
    }
}

/// (name, c_in, c_out, k, stride, groups, input at 1/2^level of the image, repeats).
type Row = (&'static str, usize, usize, usize, usize, usize, u32, usize);

/// Merge identical shapes (summing their counts and joining their names).
fn merge(model: &'static str, size: usize, rows: Vec<Row>) -> Vec<ConvShape> {
    let mut out: Vec<ConvShape> = Vec::new();
    for (name, c_in, c_out, k, stride, groups, level, count) in rows {
        let hw = size >> level;
        let key = (c_in, c_out, k, stride, groups, hw);
        match out
            .iter_mut()
            .find(|c| (c.c_in, c.c_out, c.k, c.stride, c.groups, c.hw) == key)
        {
            Some(c) => {
                c.count += count;
                if !c.name.split(" + ").any(|n| n == name) {
                    c.name = format!("{} + {name}", c.name);
                }
            }
            None => out.push(ConvShape {
                model,
                name: name.to_string(),
                c_in,
                c_out,
                k,
                stride,
                groups,
                hw,
                count,
            }),
        }
    }
    out
}

/// YOLO11n-seg (ultralytics `yolo11-seg.yaml` at scale n, one class, 32 masks, Proto
/// width 64, C2PSA on) at `size` px. The Proto's transposed convolution is not a
/// convolution and is left out.
pub fn yolo11n_seg(size: usize) -> Vec<ConvShape> {
    let mut rows: Vec<Row> = vec![
        ("b0 stem", 3, 16, 3, 2, 1, 0, 1),
        ("b1", 16, 32, 3, 2, 1, 1, 1),
        ("b2 cv1", 32, 32, 1, 1, 1, 2, 1),
        ("b2 bottleneck", 16, 16, 3, 1, 1, 2, 2),
        ("b2 cv2", 48, 64, 1, 1, 1, 2, 1),
        ("b3", 64, 64, 3, 2, 1, 2, 1),
        ("b4 cv1", 64, 64, 1, 1, 1, 3, 1),
        ("b4 bottleneck", 32, 32, 3, 1, 1, 3, 2),
        ("b4 cv2", 96, 128, 1, 1, 1, 3, 1),
        ("b5", 128, 128, 3, 2, 1, 3, 1),
        ("b6 cv1", 128, 128, 1, 1, 1, 4, 1),
        ("b6 c3k cv1/cv2", 64, 32, 1, 1, 1, 4, 2),
        ("b6 c3k bottleneck", 32, 32, 3, 1, 1, 4, 4),
        ("b6 c3k cv3", 64, 64, 1, 1, 1, 4, 1),
        ("b6 cv2", 192, 128, 1, 1, 1, 4, 1),
        ("b7", 128, 256, 3, 2, 1, 4, 1),
        ("b8/n22 cv1", 256, 256, 1, 1, 1, 5, 1),
        ("n22 cv1", 384, 256, 1, 1, 1, 5, 1),
        ("b8/n22 c3k cv1/cv2", 128, 64, 1, 1, 1, 5, 4),
        ("b8/n22 c3k bottleneck", 64, 64, 3, 1, 1, 5, 8),
        ("b8/n22 c3k cv3", 128, 128, 1, 1, 1, 5, 2),
        ("b8/n22 cv2", 384, 256, 1, 1, 1, 5, 2),
        ("sppf cv1", 256, 128, 1, 1, 1, 5, 1),
        ("sppf cv2", 512, 256, 1, 1, 1, 5, 1),
        ("psa cv1/cv2", 256, 256, 1, 1, 1, 5, 2),
        ("psa qkv / ffn1", 128, 256, 1, 1, 1, 5, 2),
        ("psa proj", 128, 128, 1, 1, 1, 5, 1),
        ("psa pe (dw)", 128, 128, 3, 1, 128, 5, 1),
        ("psa ffn2", 256, 128, 1, 1, 1, 5, 1),
        ("n13/n19 cv1", 384, 128, 1, 1, 1, 4, 1),
        ("n19 cv1", 192, 128, 1, 1, 1, 4, 1),
        ("n13/n19 bottleneck", 64, 64, 3, 1, 1, 4, 4),
        ("n13/n19 cv2", 192, 128, 1, 1, 1, 4, 2),
        ("n16 cv1", 256, 64, 1, 1, 1, 3, 1),
        ("n16 bottleneck", 32, 32, 3, 1, 1, 3, 2),
        ("n16 cv2", 96, 64, 1, 1, 1, 3, 1),
        ("n17", 64, 64, 3, 2, 1, 3, 1),
        ("n20", 128, 128, 3, 2, 1, 4, 1),
        ("proto cv1", 64, 64, 3, 1, 1, 3, 1),
        ("proto cv2", 64, 64, 3, 1, 1, 2, 1),
        ("proto cv3", 64, 32, 1, 1, 1, 2, 1),
    ];
    // Segment head, per level (channels, level): box, class and mask-coefficient branches.
    for (x, level) in [(64, 3), (128, 4), (256, 5)] {
        rows.extend([
            ("head box c1", x, 64, 3, 1, 1, level, 1),
            ("head box c2", 64, 64, 3, 1, 1, level, 1),
            ("head box out / cls pw2", 64, 64, 1, 1, 1, level, 2),
            ("head cls dw1", x, x, 3, 1, x, level, 1),
            ("head cls pw1", x, 64, 1, 1, 1, level, 1),
            ("head cls dw2", 64, 64, 3, 1, 64, level, 1),
            ("head cls out", 64, 1, 1, 1, 1, level, 1),
            ("head coef c1", x, 32, 3, 1, 1, level, 1),
            ("head coef c2", 32, 32, 3, 1, 1, level, 1),
            ("head coef out", 32, 32, 1, 1, 1, level, 1),
        ]);
    }
    merge("yolo11n-seg", size, rows)
}

/// The compact Mask R-CNN R18 (`MaskRcnnConfig::new(18, 1)`: ResNet-18, 128-wide FPN and
/// RPN, 3 anchors per cell, 128-wide mask head) at `size` px, up to the RoI heads. The
/// mask head's four 3×3 convolutions run on 14×14 RoI features, one "image" per RoI, so
/// they are listed at `hw` 14 with count 4 whatever the input size.
pub fn maskrcnn_r18(size: usize) -> Vec<ConvShape> {
    let mut shapes = merge("maskrcnn-r18", size, maskrcnn_r18_rows());
    shapes.push(ConvShape {
        model: "maskrcnn-r18",
        name: "mask head (per RoI)".to_string(),
        c_in: 128,
        c_out: 128,
        k: 3,
        stride: 1,
        groups: 1,
        hw: 14,
        count: 4,
    });
    shapes
}

/// The rows of [`maskrcnn_r18`] before merging: ResNet-18 trunk, FPN, RPN.
fn maskrcnn_r18_rows() -> Vec<Row> {
    let mut rows: Vec<Row> = vec![
        ("stem 7×7", 3, 64, 7, 2, 1, 0, 1),
        ("layer1", 64, 64, 3, 1, 1, 2, 4),
        ("layer2.0 conv1", 64, 128, 3, 2, 1, 2, 1),
        ("layer2.0 down", 64, 128, 1, 2, 1, 2, 1),
        ("layer2", 128, 128, 3, 1, 1, 3, 3),
        ("layer3.0 conv1", 128, 256, 3, 2, 1, 3, 1),
        ("layer3.0 down", 128, 256, 1, 2, 1, 3, 1),
        ("layer3", 256, 256, 3, 1, 1, 4, 3),
        ("layer4.0 conv1", 256, 512, 3, 2, 1, 4, 1),
        ("layer4.0 down", 256, 512, 1, 2, 1, 4, 1),
        ("layer4", 512, 512, 3, 1, 1, 5, 3),
    ];
    for (c, level) in [(64, 2), (128, 3), (256, 4), (512, 5)] {
        rows.push(("fpn lateral", c, 128, 1, 1, 1, level, 1));
        rows.push(("fpn output", 128, 128, 3, 1, 1, level, 1));
    }
    for level in 2..=6 {
        rows.push(("rpn conv", 128, 128, 3, 1, 1, level, 1));
        rows.push(("rpn objectness", 128, 3, 1, 1, 1, level, 1));
        rows.push(("rpn deltas", 128, 12, 1, 1, 1, level, 1));
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    fn total_macs(shapes: &[ConvShape]) -> u64 {
        shapes.iter().map(|c| c.count as u64 * c.macs()).sum()
    }

    #[test]
    fn shapes_merge_and_scale_with_the_input() {
        let s256 = yolo11n_seg(256);
        let s640 = yolo11n_seg(640);
        assert_eq!(s256.len(), s640.len());
        // Every layer is counted once (merging only sums counts): 66 backbone, neck and
        // Proto layers in 41 rows, plus 3 levels × 11 head layers.
        let layers: usize = s256.iter().map(|c| c.count).sum();
        assert_eq!(layers, 99);
        assert_eq!(s256.len(), 54);
        // Same layers, 6.25× the pixels.
        assert_eq!(total_macs(&s640) * 4, total_macs(&s256) * 25);
        let stem = &s640[0];
        assert_eq!(
            (stem.hw, stem.out_hw(), stem.macs()),
            (640, 320, 320 * 320 * 16 * 27)
        );
    }

    #[test]
    fn maskrcnn_lists_the_r18_trunk() {
        let is_trunk = |name: &str| name.starts_with("layer") || name.starts_with("stem");
        let trunk: Vec<Row> = maskrcnn_r18_rows()
            .into_iter()
            .filter(|r| is_trunk(r.0))
            .collect();
        // ResNet-18: stem + 8 basic blocks × 2 convs + 3 downsamples.
        assert_eq!(trunk.iter().map(|r| r.7).sum::<usize>(), 20);
        let net =
            crate::model::maskrcnn::resnet::ResNet::new(18, 1.0, &burn::tensor::Device::flex());
        assert_eq!(total_macs(&merge("t", 256, trunk)), net.macs([256, 256]));
        let s = maskrcnn_r18(256);
        // Merged rows keep every layer: the FPN output and RPN convolution at stride 8
        // have layer2's shape and are counted (and named) in its row.
        let layer2 = s.iter().find(|c| c.name.starts_with("layer2 ")).unwrap();
        assert_eq!(
            (layer2.name.as_str(), layer2.count),
            ("layer2 + fpn output + rpn conv", 5)
        );
        let layers: usize = s.iter().map(|c| c.count).sum();
        assert_eq!(layers, 20 + 4 * 2 + 5 * 3 + 4);
        let p6 = s
            .iter()
            .find(|c| c.name == "rpn conv" && c.hw == 4)
            .unwrap();
        assert_eq!(p6.count, 1);
    }
}
