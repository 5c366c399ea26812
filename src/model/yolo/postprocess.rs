//! Inference postprocess: decode boxes and scores, class-wise NMS, and each kept
//! detection's mask coefficients beside its image's prototypes.
//!
//! Runs in plain Rust over host copies of the output (box counts are small, and
//! burn-vision's NMS does not run on ndarray). Masks are not decoded here: the caller
//! decodes them at the size it needs ([`crate::model::instance_mask::prototype_mask`]:
//! at the original image for eval and predict, as ultralytics' `retina_masks=True`).

use std::sync::Arc;

use super::head::REG_MAX;
use super::YoloOutput;
use crate::model::detection::{nms, Detection};
use crate::model::instance_mask::{MaskSource, Prototypes};
use crate::util::tensor::to_host;

/// Decodes, filters (`score > conf`, best class per anchor), runs class-wise NMS at `iou`,
/// keeps `max_det` per image, each with its mask coefficients.
pub fn postprocess(out: &YoloOutput, conf: f32, iou: f32, max_det: usize) -> Vec<Vec<Detection>> {
    let [b, nc, na] = out.cls_logits.dims();
    let [_, nm, ph, pw] = out.proto.dims();
    let [ih, _] = out.grid.input;
    let probs = to_host(burn::tensor::activation::sigmoid(out.cls_logits.clone()));
    let dist = to_host(burn::tensor::activation::softmax(
        out.box_dist.clone().reshape([b, 4, REG_MAX, na]),
        2,
    ));
    let coef = to_host(out.mask_coef.clone());
    let proto = to_host(out.proto.clone());
    let points = out.grid.points();
    let strides = out.grid.strides();

    (0..b)
        .map(|i| {
            let mut cands = Vec::new();
            let mut anchor_of = Vec::new();
            for a in 0..na {
                let (best, cls) = best_class(nc, |c| probs[(i * nc + c) * na + a]);
                if best <= conf {
                    continue;
                }
                let mut d = [0f32; 4];
                for (k, dk) in d.iter_mut().enumerate() {
                    for r in 0..REG_MAX {
                        *dk += r as f32 * dist[((i * 4 + k) * REG_MAX + r) * na + a];
                    }
                }
                let (p, s) = (points[a], strides[a]);
                let bx = [
                    (p[0] - d[0]) * s,
                    (p[1] - d[1]) * s,
                    (p[0] + d[2]) * s,
                    (p[1] + d[3]) * s,
                ];
                cands.push((bx, best, cls));
                anchor_of.push(a);
            }
            let protos = prototypes(
                &proto[i * nm * ph * pw..(i + 1) * nm * ph * pw],
                [nm, ph, pw],
                ih,
            );
            kept(&cands, &anchor_of, (iou, max_det), protos, |a, m| {
                coef[(i * nm + m) * na + a]
            })
        })
        .collect()
}

/// The same postprocess on ultralytics' ONNX layout (what an exported file outputs, see
/// [`super::onnx`]): `output0` `[B, 4 + nc + nm, A]` with xywh boxes in input pixels and
/// sigmoid scores, `proto` `[B, nm, ph, pw]`, both row-major; `input = [H, W]`.
pub fn postprocess_layout(
    output0: (&[f32], [usize; 3]),
    proto: (&[f32], [usize; 4]),
    num_classes: usize,
    input: [usize; 2],
    (conf, iou, max_det): (f32, f32, usize),
) -> Vec<Vec<Detection>> {
    let (y, [b, no, na]) = output0;
    let (proto, [_, nm, ph, pw]) = proto;
    let nc = num_classes;
    debug_assert_eq!(no, 4 + nc + nm);
    let at = |i: usize, ch: usize, a: usize| y[(i * no + ch) * na + a];
    (0..b)
        .map(|i| {
            let mut cands = Vec::new();
            let mut anchor_of = Vec::new();
            for a in 0..na {
                let (best, cls) = best_class(nc, |c| at(i, 4 + c, a));
                if best <= conf {
                    continue;
                }
                let (cx, cy, w, h) = (at(i, 0, a), at(i, 1, a), at(i, 2, a), at(i, 3, a));
                let bx = [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0];
                cands.push((bx, best, cls));
                anchor_of.push(a);
            }
            let protos = prototypes(
                &proto[i * nm * ph * pw..(i + 1) * nm * ph * pw],
                [nm, ph, pw],
                input[0],
            );
            kept(&cands, &anchor_of, (iou, max_det), protos, |a, m| {
                at(i, 4 + nc + m, a)
            })
        })
        .collect()
}

/// The best class of an anchor and its score (the first of equal scores).
fn best_class(nc: usize, score: impl Fn(usize) -> f32) -> (f32, usize) {
    let (mut best, mut cls) = (f32::NEG_INFINITY, 0);
    for c in 0..nc {
        let p = score(c);
        if p > best {
            best = p;
            cls = c;
        }
    }
    (best, cls)
}

/// One image's `[nm, ph, pw]` prototypes, shared by its detections; `input_h` gives the
/// stride.
fn prototypes(data: &[f32], [nm, ph, pw]: [usize; 3], input_h: usize) -> Arc<Prototypes> {
    Arc::new(Prototypes {
        data: data.to_vec(),
        channels: nm,
        height: ph,
        width: pw,
        stride: (input_h / ph.max(1)).max(1),
    })
}

/// Class-wise NMS over one image's candidates (xyxy, score, class; `anchor_of` their
/// anchors) and the kept detections, each with its mask coefficients `coef(anchor, m)`.
fn kept(
    cands: &[([f32; 4], f32, usize)],
    anchor_of: &[usize],
    (iou, max_det): (f32, usize),
    protos: Arc<Prototypes>,
    coef: impl Fn(usize, usize) -> f32,
) -> Vec<Detection> {
    let nm = protos.channels;
    nms(cands, iou, max_det)
        .into_iter()
        .map(|k| {
            let (bx, score, class) = cands[k];
            Detection {
                bbox: [bx[0], bx[1], bx[2] - bx[0], bx[3] - bx[1]],
                score,
                class,
                mask: MaskSource::Prototypes {
                    coef: (0..nm).map(|m| coef(anchor_of[k], m)).collect(),
                    protos: protos.clone(),
                },
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nms_is_class_wise_and_ordered() {
        let c = vec![
            ([0.0, 0.0, 10.0, 10.0], 0.9, 0),
            ([1.0, 1.0, 10.0, 10.0], 0.8, 0), // suppressed by 0
            ([1.0, 1.0, 10.0, 10.0], 0.7, 1), // other class: kept
            ([50.0, 50.0, 60.0, 60.0], 0.95, 0),
        ];
        assert_eq!(nms(&c, 0.7, 300), vec![3, 0, 2]);
        assert_eq!(nms(&c, 0.7, 2), vec![3, 0]);
        assert!(nms(&[], 0.7, 300).is_empty());
    }
}
