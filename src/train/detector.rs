//! The models the trainer can train, behind one closed interface (an enum, like pbrt's
//! tagged unions): build from the run config, loss of a batch with named terms, inference
//! to [`Detection`]s for the shared COCO evaluation, summary. Everything else the trainer
//! does (optimiser, EMA, clipping, checkpoints) works on any Burn [`Module`], so it serves
//! both variants unchanged.

use anyhow::{bail, Result};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::{Config, MaskRcnnPreset, ModelKind};
use crate::model::maskrcnn::anchors::AnchorConfig;
use crate::model::maskrcnn::{MaskRcnn, MaskRcnnConfig};
use crate::model::yolo::loss::{yolo_loss, LossWeights, YoloTargets};
use crate::model::yolo::postprocess::{postprocess, Detection};
use crate::model::yolo::{HeadLevels, ModelSummary, Scale, YoloSeg, YoloSegConfig};

use super::evaluate::{VAL_IOU, VAL_MAX_DET};

/// Model config of a checkpoint: the kind and everything needed to rebuild the weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum DetectorConfig {
    Yolo(YoloSegConfig),
    Maskrcnn(MaskRcnnConfig),
}

/// A trainable instance-segmentation model.
#[derive(Module, Debug)]
pub enum Detector {
    Yolo(YoloSeg),
    MaskRcnn(MaskRcnn),
}

/// Loss of one training batch: the tensor to back-propagate and the host values of its
/// named terms (in [`Detector::loss_names`] order) and of the total.
pub struct StepLoss {
    pub total: Tensor<1>,
    pub terms: Vec<f32>,
    pub total_value: f32,
}

impl DetectorConfig {
    /// The model of run config `cfg` with `nc` classes.
    pub fn from_config(cfg: &Config, nc: usize) -> Result<Self> {
        let m = &cfg.model;
        if nc == 0 {
            bail!("the data has no categories to train on");
        }
        Ok(match m.kind {
            ModelKind::Yolo => DetectorConfig::Yolo(
                YoloSegConfig::new(if m.scale() == "s" { Scale::S } else { Scale::N }, nc)
                    .with_input_size(cfg.data.image_size as usize)
                    .with_levels(if m.levels() == [4, 5] {
                        HeadLevels::P4P5
                    } else {
                        HeadLevels::P3P5
                    })
                    .with_c2psa(m.c2psa())
                    .with_width_mult(m.width_mult)
                    .with_num_masks(m.prototypes()),
            ),
            ModelKind::Maskrcnn => {
                let depth = m.depth();
                let mut c = match m.preset() {
                    MaskRcnnPreset::Compact => MaskRcnnConfig::new(depth, nc),
                    MaskRcnnPreset::Paper => MaskRcnnConfig::paper(depth, nc),
                }
                .with_width_mult(m.width_mult)
                .with_input_size(cfg.data.image_size as usize);
                if let Some(f) = m.fpn_channels {
                    c.fpn_channels = f;
                }
                if let Some(s) = &m.anchor_sizes {
                    c.anchors = AnchorConfig {
                        sizes: s.clone(),
                        ..c.anchors
                    };
                }
                let r = &mut c.rpn;
                r.batch_per_image = m.rpn_batch.unwrap_or(r.batch_per_image);
                r.pre_nms_topk_train = m.rpn_pre_nms_topk_train.unwrap_or(r.pre_nms_topk_train);
                r.post_nms_topk_train = m.rpn_post_nms_topk_train.unwrap_or(r.post_nms_topk_train);
                r.pre_nms_topk_test = m.rpn_pre_nms_topk_test.unwrap_or(r.pre_nms_topk_test);
                r.post_nms_topk_test = m.rpn_post_nms_topk_test.unwrap_or(r.post_nms_topk_test);
                c.roi.batch_per_image = m.roi_batch.unwrap_or(c.roi.batch_per_image);
                c.roi.fc_dim = m.box_fc_dim.unwrap_or(c.roi.fc_dim);
                c.mask.conv_dim = m.mask_conv_dim.unwrap_or(c.mask.conv_dim);
                c.mask.class_agnostic = m.mask_class_agnostic.unwrap_or(c.mask.class_agnostic);
                DetectorConfig::Maskrcnn(c)
            }
        })
    }

    pub fn kind(&self) -> ModelKind {
        match self {
            DetectorConfig::Yolo(_) => ModelKind::Yolo,
            DetectorConfig::Maskrcnn(_) => ModelKind::Maskrcnn,
        }
    }

    pub fn num_classes(&self) -> usize {
        match self {
            DetectorConfig::Yolo(c) => c.num_classes,
            DetectorConfig::Maskrcnn(c) => c.num_classes,
        }
    }

    /// Square inference input size (px).
    pub fn input_size(&self) -> usize {
        match self {
            DetectorConfig::Yolo(c) => c.input_size,
            DetectorConfig::Maskrcnn(c) => c.input_size,
        }
    }

    pub fn init(&self, device: &Device) -> Detector {
        match self {
            DetectorConfig::Yolo(c) => Detector::Yolo(c.init(device)),
            DetectorConfig::Maskrcnn(c) => Detector::MaskRcnn(c.init(device)),
        }
    }

    /// One line naming the architecture.
    pub fn describe(&self) -> String {
        match self {
            DetectorConfig::Yolo(c) => format!(
                "YOLO-seg {} {:?}, c2psa {}, width ×{}, {} classes",
                c.scale.name(),
                c.levels,
                c.c2psa,
                c.width_mult,
                c.num_classes
            ),
            DetectorConfig::Maskrcnn(c) => format!(
                "Mask R-CNN R{}-FPN, width ×{}, FPN {}, RoIs {}/image, {} classes",
                c.depth, c.width_mult, c.fpn_channels, c.roi.batch_per_image, c.num_classes
            ),
        }
    }

    /// Why a checkpoint's model cannot continue or replace this one, if it cannot.
    pub fn mismatch(&self, other: &DetectorConfig) -> Option<String> {
        let name = |k: ModelKind| match k {
            ModelKind::Yolo => "model.kind = \"yolo\"",
            ModelKind::Maskrcnn => "model.kind = \"maskrcnn\"",
        };
        if self.kind() != other.kind() {
            return Some(format!(
                "it holds a {} model, the config asks for {}",
                name(other.kind()),
                name(self.kind())
            ));
        }
        if self.num_classes() != other.num_classes() {
            return Some(format!(
                "it has {} classes, the data has {}",
                other.num_classes(),
                self.num_classes()
            ));
        }
        (self != other).then(|| format!("its model {other:?} differs from the config's {self:?}"))
    }
}

impl Detector {
    /// Names of the loss terms, as logged in `metrics.jsonl` (`loss.<name>`).
    pub fn loss_names(&self) -> &'static [&'static str] {
        match self {
            Detector::Yolo(_) => &["box", "cls", "dfl", "seg"],
            Detector::MaskRcnn(_) => &["rpn_cls", "rpn_box", "cls", "box", "mask"],
        }
    }

    /// Training loss of a batch. `images` are `[B, 3, H, W]` in `[0, 1]` (Mask R-CNN
    /// normalises inside); `sample_seed` drives Mask R-CNN's anchor and RoI sampling, so a
    /// step does not depend on what ran before it.
    pub fn loss(&self, images: Tensor<4>, targets: &YoloTargets, sample_seed: u64) -> StepLoss {
        match self {
            Detector::Yolo(m) => {
                let out = m.forward(images);
                let l = yolo_loss(&out, targets, &LossWeights::default());
                let v = l.values();
                StepLoss {
                    total: l.total,
                    terms: v[..4].to_vec(),
                    total_value: v[4],
                }
            }
            Detector::MaskRcnn(m) => {
                let mut rng = ChaCha8Rng::seed_from_u64(sample_seed);
                let l = m.forward_train(images, &targets.images, &mut rng);
                let v = l.values();
                StepLoss {
                    total: l.total,
                    terms: v[..5].to_vec(),
                    total_value: v[5],
                }
            }
        }
    }

    /// Detections per image with score ≥ `conf` (call on the eval-mode, plain-device model).
    /// Mask R-CNN applies its own score threshold (`roi.score_thresh`, 0.05) first.
    pub fn predict(&self, images: Tensor<4>, conf: f32) -> Vec<Vec<Detection>> {
        match self {
            Detector::Yolo(m) => postprocess(&m.forward(images), conf, VAL_IOU, VAL_MAX_DET),
            Detector::MaskRcnn(m) => {
                let mut out = m.forward_infer(images);
                for d in &mut out {
                    d.retain(|x| x.score >= conf);
                }
                out
            }
        }
    }

    pub fn summary(&self, input: usize) -> ModelSummary {
        match self {
            Detector::Yolo(m) => m.summary(input),
            Detector::MaskRcnn(m) => m.summary(input),
        }
    }
}
