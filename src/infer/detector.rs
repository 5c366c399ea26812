//! The models the trainer can train, behind one closed interface (an enum, like pbrt's
//! tagged unions): build from the run config, loss of a batch with named terms, inference
//! to [`Detection`]s for the shared COCO evaluation, summary. Everything else the trainer
//! does (optimiser, EMA, clipping, checkpoints) works on any Burn [`Module`], so it serves
//! every variant unchanged.

use anyhow::{bail, Result};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::{Config, ModelConfig, ModelKind};
use crate::data::targets::Targets;
use crate::model::detection::{nms_detections, Detection};
use crate::model::mask2former::{Mask2Former, Mask2FormerConfig, Mask2FormerLosses};
use crate::model::maskrcnn::{MaskRcnn, MaskRcnnConfig, MaskRcnnLosses};
use crate::model::summary::ModelSummary;
use crate::model::yolo::loss::{yolo_loss, LossTerms, LossWeights};
use crate::model::yolo::postprocess::postprocess;
use crate::model::yolo::{YoloSeg, YoloSegConfig};

/// Validation postprocess settings of YOLO (ultralytics' val defaults; Mask R-CNN uses
/// only `VAL_CONF`, below its own threshold).
pub const VAL_CONF: f32 = 0.001;
pub const VAL_IOU: f32 = 0.7;
pub const VAL_MAX_DET: usize = 300;

/// Model config of a checkpoint: the kind and everything needed to rebuild the weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum DetectorConfig {
    Yolo(YoloSegConfig),
    Maskrcnn(MaskRcnnConfig),
    Mask2former(Mask2FormerConfig),
}

/// A trainable instance-segmentation model.
#[derive(Module, Debug)]
pub enum Detector {
    Yolo(YoloSeg),
    MaskRcnn(MaskRcnn),
    Mask2Former(Mask2Former),
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
        let input = cfg.data.image_size as usize;
        Ok(match m {
            ModelConfig::Yolo(m) => DetectorConfig::Yolo(YoloSegConfig::from_config(m, input, nc)),
            ModelConfig::Maskrcnn(m) => {
                DetectorConfig::Maskrcnn(MaskRcnnConfig::from_config(m, input, nc))
            }
            ModelConfig::Mask2former(m) => {
                DetectorConfig::Mask2former(Mask2FormerConfig::from_config(m, input, nc))
            }
        })
    }

    pub fn kind(&self) -> ModelKind {
        match self {
            DetectorConfig::Yolo(_) => ModelKind::Yolo,
            DetectorConfig::Maskrcnn(_) => ModelKind::Maskrcnn,
            DetectorConfig::Mask2former(_) => ModelKind::Mask2former,
        }
    }

    pub fn num_classes(&self) -> usize {
        match self {
            DetectorConfig::Yolo(c) => c.num_classes,
            DetectorConfig::Maskrcnn(c) => c.num_classes,
            DetectorConfig::Mask2former(c) => c.num_classes,
        }
    }

    /// Square inference input size (px).
    pub fn input_size(&self) -> usize {
        match self {
            DetectorConfig::Yolo(c) => c.input_size,
            DetectorConfig::Maskrcnn(c) => c.input_size,
            DetectorConfig::Mask2former(c) => c.input_size,
        }
    }

    pub fn init(&self, device: &Device) -> Detector {
        match self {
            DetectorConfig::Yolo(c) => Detector::Yolo(c.init(device)),
            DetectorConfig::Maskrcnn(c) => Detector::MaskRcnn(c.init(device)),
            DetectorConfig::Mask2former(c) => Detector::Mask2Former(c.init(device)),
        }
    }

    /// Module-path prefixes of the stages `train.freeze = n` freezes (see `model::freeze`).
    pub fn frozen_prefixes(&self, n: usize) -> Result<Vec<String>> {
        match self {
            DetectorConfig::Yolo(_) => crate::model::freeze::yolo_prefixes(n),
            DetectorConfig::Maskrcnn(_) => crate::model::freeze::maskrcnn_prefixes(n),
            // Same ResNet, same module paths.
            DetectorConfig::Mask2former(_) => crate::model::freeze::maskrcnn_prefixes(n),
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
            DetectorConfig::Mask2former(c) => format!(
                "Mask2Former R{} (FPN pixel decoder), width ×{}, {} queries, {} layers × {} wide, {} points, {} classes",
                c.depth,
                c.width_mult,
                c.queries,
                c.dec_layers,
                c.hidden_dim,
                c.criterion.points,
                c.num_classes
            ),
        }
    }

    /// Why a checkpoint's model cannot continue or replace this one, if it cannot.
    pub fn mismatch(&self, other: &DetectorConfig) -> Option<String> {
        let name = |k: ModelKind| match k {
            ModelKind::Yolo => "model.kind = \"yolo\"",
            ModelKind::Maskrcnn => "model.kind = \"maskrcnn\"",
            ModelKind::Mask2former => "model.kind = \"mask2former\"",
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
            Detector::Yolo(_) => &LossTerms::NAMES,
            Detector::MaskRcnn(_) => &MaskRcnnLosses::NAMES,
            Detector::Mask2Former(_) => &Mask2FormerLosses::NAMES,
        }
    }

    /// Training loss of a batch. `images` are `[B, 3, H, W]` in `[0, 1]` (Mask R-CNN
    /// and Mask2Former normalise inside); `sample_seed` drives Mask R-CNN's anchor and RoI
    /// sampling and Mask2Former's point sampling, so a step does not depend on what ran
    /// before it.
    pub fn loss(&self, images: Tensor<4>, targets: &Targets, sample_seed: u64) -> StepLoss {
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
            Detector::Mask2Former(m) => {
                let mut rng = ChaCha8Rng::seed_from_u64(sample_seed);
                let l = m.forward_train(images, &targets.images, &mut rng);
                let v = l.values();
                StepLoss {
                    total: l.total,
                    terms: v[..3].to_vec(),
                    total_value: v[3],
                }
            }
        }
    }

    /// Detections per image with score ≥ `conf` (call on the eval-mode, plain-device model).
    /// Mask R-CNN applies its own score threshold (`roi.score_thresh`, 0.05) first.
    pub fn predict(&self, images: Tensor<4>, conf: f32) -> Vec<Vec<Detection>> {
        self.predict_timed(images, conf).0
    }

    /// [`Self::predict`] with the NMS IoU and detection cap of `predict --iou --max-det`:
    /// YOLO's postprocess runs at them; Mask R-CNN's and Mask2Former's detections (their
    /// own NMS already applied) go through [`nms_detections`] at them.
    pub fn predict_nms(
        &self,
        images: Tensor<4>,
        conf: f32,
        iou: f32,
        max_det: usize,
    ) -> Vec<Vec<Detection>> {
        match self {
            Detector::Yolo(m) => postprocess(&m.forward(images), conf, iou, max_det),
            _ => self
                .predict(images, conf)
                .into_iter()
                .map(|d| nms_detections(d, iou, max_det))
                .collect(),
        }
    }

    /// [`Self::predict`] and the seconds of the network alone: YOLO's forward pass up to
    /// its output tensors (box decoding and NMS excluded); Mask R-CNN's `forward_infer`
    /// whole (its proposal, NMS and head stages interleave with the network); Mask2Former's
    /// `forward_infer` whole (network and top-k postprocess). Wall clock
    /// on the eager CPU backends; a lazy GPU backend would move time into the postprocess.
    pub fn predict_timed(&self, images: Tensor<4>, conf: f32) -> (Vec<Vec<Detection>>, f64) {
        let t = std::time::Instant::now();
        match self {
            Detector::Yolo(m) => {
                let out = m.forward(images);
                let fwd = t.elapsed().as_secs_f64();
                (postprocess(&out, conf, VAL_IOU, VAL_MAX_DET), fwd)
            }
            Detector::MaskRcnn(m) => {
                let mut out = m.forward_infer(images);
                for d in &mut out {
                    d.retain(|x| x.score >= conf);
                }
                (out, t.elapsed().as_secs_f64())
            }
            Detector::Mask2Former(m) => {
                let mut out = m.forward_infer(images);
                for d in &mut out {
                    d.retain(|x| x.score >= conf);
                }
                (out, t.elapsed().as_secs_f64())
            }
        }
    }

    pub fn summary(&self, input: usize) -> ModelSummary {
        match self {
            Detector::Yolo(m) => m.summary(input),
            Detector::MaskRcnn(m) => m.summary(input),
            Detector::Mask2Former(m) => m.summary(input),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config;

    fn load(name: &str, ov: &[&str]) -> Config {
        let ov: Vec<String> = ov.iter().map(|s| s.to_string()).collect();
        config::load(name, &ov).unwrap()
    }

    #[test]
    fn config_keys_reach_the_model_config() {
        let c = DetectorConfig::from_config(&load("maskrcnn_r101_syn1000", &[]), 1).unwrap();
        let DetectorConfig::Maskrcnn(m) = &c else {
            panic!("{c:?}")
        };
        assert_eq!(
            m,
            &MaskRcnnConfig::new(101, 1).with_input_size(640),
            "compact preset, 640 px"
        );
        let c = DetectorConfig::from_config(
            &load(
                "maskrcnn_r50_syn750",
                &[
                    "model.preset=\"paper\"",
                    "model.roi_batch=64",
                    "model.anchor_sizes=[16.0, 32.0, 64.0, 128.0, 256.0]",
                    "model.mask_class_agnostic=true",
                    "model.rpn_post_nms_topk_test=77",
                ],
            ),
            2,
        )
        .unwrap();
        let DetectorConfig::Maskrcnn(m) = &c else {
            panic!("{c:?}")
        };
        assert_eq!((m.depth, m.num_classes, m.fpn_channels), (50, 2, 256));
        assert_eq!(m.roi.batch_per_image, 64);
        assert_eq!(m.roi.fc_dim, 1024, "paper preset kept where not overridden");
        assert_eq!(m.anchors.sizes, [16.0, 32.0, 64.0, 128.0, 256.0]);
        assert!(m.mask.class_agnostic);
        assert_eq!(m.rpn.post_nms_topk_test, 77);
        let y = DetectorConfig::from_config(&load("quickstart", &[]), 1).unwrap();
        assert_eq!(y.kind(), ModelKind::Yolo);
        assert_eq!(y.input_size(), 256);
    }

    #[test]
    fn mask2former_keys_reach_the_model_config() {
        let c = DetectorConfig::from_config(&load("mask2former_syn500", &[]), 1).unwrap();
        let DetectorConfig::Mask2former(m) = &c else {
            panic!("{c:?}")
        };
        let mut want = Mask2FormerConfig::new(50, 1);
        want.input_size = 640;
        assert_eq!(m, &want, "compact preset, 25 queries, 640 px");
        let c = DetectorConfig::from_config(
            &load(
                "mask2former_syn750",
                &[
                    "model.preset=\"paper\"",
                    "model.queries=30",
                    "model.points=999",
                    "model.depth=101",
                ],
            ),
            2,
        )
        .unwrap();
        let DetectorConfig::Mask2former(m) = &c else {
            panic!("{c:?}")
        };
        assert_eq!((m.depth, m.num_classes, m.queries), (101, 2, 30));
        assert_eq!(
            (m.hidden_dim, m.dec_layers, m.criterion.points),
            (256, 9, 999)
        );
        let y = DetectorConfig::from_config(&load("quickstart", &[]), 1).unwrap();
        let e = c.mismatch(&y).unwrap();
        assert!(e.contains("asks for model.kind = \"mask2former\""), "{e}");
        let bad = config::load(
            "mask2former_syn250",
            &["model.hidden_dim=100".into(), "model.heads=8".into()],
        );
        let e = format!("{:#}", bad.unwrap_err());
        assert!(
            e.contains("model.hidden_dim = 100 must be even and a multiple of model.heads = 8"),
            "{e}"
        );
    }

    #[test]
    fn mismatches_name_the_kind_and_the_class_count() {
        let m = DetectorConfig::from_config(&load("maskrcnn_r50_syn250", &[]), 1).unwrap();
        let y = DetectorConfig::from_config(&load("quickstart", &[]), 1).unwrap();
        let m3 = DetectorConfig::from_config(&load("maskrcnn_r50_syn250", &[]), 3).unwrap();
        assert_eq!(m.mismatch(&m.clone()), None);
        let e = m.mismatch(&y).unwrap();
        assert!(
            e.contains("holds a model.kind = \"yolo\" model")
                && e.contains("asks for model.kind = \"maskrcnn\""),
            "{e}"
        );
        let e = m.mismatch(&m3).unwrap();
        assert!(e.contains("it has 3 classes, the data has 1"), "{e}");
    }
}
