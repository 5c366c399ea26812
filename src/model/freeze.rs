//! Freezing the first stages of a model (`train.freeze = N`, ultralytics' `freeze`):
//! their weights stop taking gradients (so the optimiser neither steps nor decays them) and
//! their BatchNorm layers run in eval mode (running statistics stay as loaded), through
//! Burn 0.22's per-layer training flag.
//!
//! Which stages `train.freeze = N` names is each family's (`Family::frozen_prefixes` in
//! `model/<family>/family.rs`: ultralytics' layer indices for YOLO, detectron2's
//! `FREEZE_AT` for the ResNet families); this file is the mechanism they share.
//!
//! Unlike ultralytics, whose frozen BatchNorm layers keep updating their running statistics
//! in train mode, frozen BatchNorm here is fully frozen, as detectron2's `FrozenBatchNorm2d`.

use burn::module::{Flag, Module, ModuleMapper, Param};
use burn::tensor::Tensor;

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
    fn frozen_paths_are_whole_segments() {
        let p = vec!["backbone.l0".to_string(), "backbone.l1".to_string()];
        assert!(is_frozen("backbone.l1.conv.weight", &p));
        assert!(!is_frozen("backbone.l10.conv.weight", &p));
        assert!(!is_frozen("backbone.l2.cv1.conv.weight", &p));
    }
}
