//! Freezing the first stages of a model (`train.freeze = N`, ultralytics' `freeze`):
//! their weights stop taking gradients (so the optimiser neither steps nor decays them) and
//! their BatchNorm layers run in eval mode (running statistics stay as loaded), through
//! Burn 0.22's per-layer training flag.
//!
//! The stages, by family:
//! - YOLO: ultralytics' layer indices of `yolo11-seg.yaml`: `freeze = N` freezes layers
//!   `0..N` (`model.0` … `model.{N-1}`): 0–8 the backbone convs and C3k2s, 9 SPPF, 10 C2PSA,
//!   13/16/17/19/20/22 the neck's C3k2s and convs (11, 12, 14, 15, 18, 21 are upsamples and
//!   concatenations without weights), 23 the head. `freeze = 10` is the backbone without
//!   C2PSA, `11` the whole backbone.
//! - Mask R-CNN: detectron2's `FREEZE_AT`: 1 the stem, 2 the stem and res2 (torchvision's
//!   `trainable_backbone_layers = 3`, both libraries' default for fine-tuning), … 5 the whole
//!   ResNet (torchvision's `trainable_backbone_layers = 0`).
//!
//! Unlike ultralytics, whose frozen BatchNorm layers keep updating their running statistics
//! in train mode, frozen BatchNorm here is fully frozen, as detectron2's `FrozenBatchNorm2d`.

use anyhow::{bail, Result};
use burn::module::{Flag, Module, ModuleMapper, Param};
use burn::tensor::Tensor;

/// Module-path prefixes of YOLO layers `0..n` (ultralytics indices).
pub fn yolo_prefixes(n: usize) -> Result<Vec<String>> {
    const LAYERS: [Option<&str>; 24] = [
        Some("backbone.l0"),
        Some("backbone.l1"),
        Some("backbone.l2"),
        Some("backbone.l3"),
        Some("backbone.l4"),
        Some("backbone.l5"),
        Some("backbone.l6"),
        Some("backbone.l7"),
        Some("backbone.l8"),
        Some("backbone.sppf"),
        Some("backbone.psa"),
        None,
        None,
        Some("neck.td_p4"),
        None,
        None,
        Some("neck.p3.td_p3"),
        Some("neck.p3.down_p3"),
        None,
        Some("neck.p3.bu_p4"),
        Some("neck.down_p4"),
        None,
        Some("neck.bu_p5"),
        Some("head"),
    ];
    if n >= LAYERS.len() {
        bail!(
            "train.freeze = {n} would freeze the whole YOLO model (layers 0..{}); use at most {}",
            LAYERS.len(),
            LAYERS.len() - 1
        );
    }
    Ok(LAYERS[..n]
        .iter()
        .flatten()
        .map(|s| s.to_string())
        .collect())
}

/// Module-path prefixes of the Mask R-CNN stem and the first `n − 1` ResNet stages
/// (detectron2's `FREEZE_AT = n`).
pub fn maskrcnn_prefixes(n: usize) -> Result<Vec<String>> {
    if n > 5 {
        bail!(
            "train.freeze = {n} must be at most 5 for a Mask R-CNN (the stem and 4 ResNet stages)"
        );
    }
    let mut p = Vec::new();
    if n >= 1 {
        p.push("backbone.stem".to_string());
    }
    for s in 0..n.saturating_sub(1) {
        p.push(format!("backbone.stages.{s}"));
    }
    Ok(p)
}

/// Whether the tensor at `path` lies in one of the frozen `prefixes`.
pub fn is_frozen(path: &str, prefixes: &[String]) -> bool {
    prefixes.iter().any(|p| {
        path.len() > p.len() && path.starts_with(p.as_str()) && path.as_bytes()[p.len()] == b'.'
    })
}

/// The module path of a visitor or mapper as the stage prefixes read it: enum variants
/// (`Detector::Yolo`, `C3k2Inner::C3k`) are not path segments, so the prefixes read the
/// same on a `Detector` and on the model inside it. Feed it `enter_module` /
/// `exit_module`.
#[derive(Debug, Default)]
pub struct StagePath(Vec<String>);

impl StagePath {
    pub fn enter(&mut self, name: &str, container: &str) {
        if !container.starts_with("Enum:") {
            self.0.push(name.to_string());
        }
    }

    pub fn exit(&mut self, container: &str) {
        if !container.starts_with("Enum:") {
            self.0.pop();
        }
    }

    /// Whether the current tensor lies in one of the frozen `prefixes`.
    pub fn frozen(&self, prefixes: &[String]) -> bool {
        is_frozen(&self.0.join("."), prefixes)
    }
}

/// Freezes every module under `prefixes`: no gradients, BatchNorm in eval mode.
pub fn freeze<M: Module>(module: M, prefixes: &[String]) -> M {
    struct F<'a> {
        path: StagePath,
        prefixes: &'a [String],
    }
    impl ModuleMapper for F<'_> {
        fn enter_module(&mut self, name: &str, container: &str) {
            self.path.enter(name, container);
        }
        fn exit_module(&mut self, _: &str, container: &str) {
            self.path.exit(container);
        }
        fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
            if self.path.frozen(self.prefixes) {
                p.set_require_grad(false)
            } else {
                p
            }
        }
        fn map_flag(&mut self, f: Param<Flag>) -> Param<Flag> {
            if self.path.frozen(self.prefixes) {
                f.with_value(false)
            } else {
                f
            }
        }
    }
    if prefixes.is_empty() {
        return module;
    }
    module.map(&mut F {
        path: StagePath::default(),
        prefixes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_tables() {
        assert!(yolo_prefixes(0).unwrap().is_empty());
        assert_eq!(
            yolo_prefixes(2).unwrap(),
            vec!["backbone.l0", "backbone.l1"]
        );
        let b = yolo_prefixes(11).unwrap();
        assert_eq!(b.len(), 11);
        assert_eq!(b.last().unwrap(), "backbone.psa");
        assert_eq!(yolo_prefixes(14).unwrap().last().unwrap(), "neck.td_p4");
        assert!(format!("{}", yolo_prefixes(24).unwrap_err()).contains("at most 23"));
        assert_eq!(
            maskrcnn_prefixes(2).unwrap(),
            vec!["backbone.stem", "backbone.stages.0"]
        );
        assert_eq!(maskrcnn_prefixes(5).unwrap().len(), 5);
        assert!(maskrcnn_prefixes(6).is_err());
        let p = yolo_prefixes(2).unwrap();
        assert!(is_frozen("backbone.l1.conv.weight", &p));
        assert!(!is_frozen("backbone.l10.conv.weight", &p));
        assert!(!is_frozen("backbone.l2.cv1.conv.weight", &p));
    }
}
