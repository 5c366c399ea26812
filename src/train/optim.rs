//! Optimisers and gradient clipping.
//!
//! - SGD with PyTorch's semantics (momentum, dampening 0 — Burn's default is 0.1 —
//!   optional Nesterov, L2 weight decay) or AdamW (β1 = `momentum`, like ultralytics,
//!   β2 0.999, ε 1e-8 as in PyTorch).
//! - No weight decay on biases and BatchNorm γ/β: a second Burn parameter group matched
//!   on the parameter path (`…bias`, `…gamma`, `…beta`), ultralytics' three groups folded
//!   into two (both groups get the same learning rate; see `schedule`).
//! - Global-norm gradient clipping over all gradients (`torch.nn.utils.clip_grad_norm_`):
//!   Burn's built-in clipping is per tensor.

use anyhow::Result;
use burn::module::{Module, ModuleVisitor, Param, ParamGroup};
use burn::optim::decay::WeightDecayConfig;
use burn::optim::momentum::MomentumConfig;
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer, SgdConfig};
use burn::tensor::{FloatDType, Tensor};

use crate::config::{OptimizerKind, TrainConfig};

/// Parameters exempt from weight decay: biases and normalisation scales/shifts.
pub const NO_DECAY: &str = r"(^|\.)(bias|gamma|beta)$";

/// The group of [`NO_DECAY`] parameters.
pub fn no_decay_group() -> ParamGroup {
    ParamGroup::from_regex(NO_DECAY).expect("NO_DECAY is a valid regex")
}

/// Builds the optimiser of `t` with the no-decay group.
pub fn build(t: &TrainConfig) -> ModuleOptimizer {
    match t.optimizer {
        OptimizerKind::Sgd => {
            let momentum = (t.momentum > 0.0).then(|| MomentumConfig {
                momentum: t.momentum,
                dampening: 0.0,
                nesterov: t.nesterov,
            });
            let decayed = SgdConfig::new()
                .with_momentum(momentum.clone())
                .with_weight_decay((t.weight_decay > 0.0).then_some(WeightDecayConfig {
                    penalty: t.weight_decay as f32,
                }));
            let plain = SgdConfig::new().with_momentum(momentum);
            decayed
                .init()
                .with_group(no_decay_group(), plain.build(), None)
        }
        OptimizerKind::Adamw => {
            let base = AdamWConfig::new()
                .with_beta_1(t.momentum as f32)
                .with_beta_2(0.999)
                .with_epsilon(1e-8);
            base.clone()
                .with_weight_decay(t.weight_decay as f32)
                .init()
                .with_group(no_decay_group(), base.with_weight_decay(0.0).build(), None)
        }
    }
}

struct SumSquares<'a> {
    grads: &'a GradientsParams,
    acc: Option<Tensor<1>>,
}

impl ModuleVisitor for SumSquares<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            // Summed in f32: f16 squares overflow (a no-op cast on the f32 path).
            let s = g.cast(FloatDType::F32).powi_scalar(2).sum();
            self.acc = Some(match self.acc.take() {
                Some(a) => a + s,
                None => s,
            });
        }
    }
}

struct Scale<'a> {
    grads: &'a mut GradientsParams,
    factor: f32,
}

impl ModuleVisitor for Scale<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.remove::<D>(param.id) {
            self.grads.register(param.id, g.mul_scalar(self.factor));
        }
    }
}

/// L2 norm of all gradients of `module` (one device sync).
pub fn grad_norm<M: Module>(module: &M, grads: &GradientsParams) -> f64 {
    let mut v = SumSquares { grads, acc: None };
    module.visit(&mut v);
    match v.acc {
        Some(t) => (crate::util::tensor::scalar(&t) as f64).sqrt(),
        None => 0.0,
    }
}

/// Multiplies every gradient of `module` by `factor` (f16 loss scaling's unscale).
pub fn scale_grads<M: Module>(module: &M, grads: &mut GradientsParams, factor: f32) {
    module.visit(&mut Scale { grads, factor });
}

/// The factor global-norm clipping multiplies the gradients by: `max_norm / norm` when
/// the norm exceeds `max_norm` (PyTorch adds 1e-6 to the denominator), else 1.
pub fn clip_factor(norm: f64, max_norm: f64) -> f64 {
    if norm > max_norm {
        max_norm / (norm + 1e-6)
    } else {
        1.0
    }
}

/// Scales all gradients by [`clip_factor`] when the global norm exceeds `max_norm`.
/// Returns the norm before clipping.
pub fn clip_global_norm<M: Module>(
    module: &M,
    grads: &mut GradientsParams,
    max_norm: f64,
) -> Result<f64> {
    let norm = grad_norm(module, grads);
    if norm.is_finite() && norm > max_norm {
        let factor = clip_factor(norm, max_norm) as f32;
        module.visit(&mut Scale { grads, factor });
    }
    Ok(norm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::yolo::{Scale, YoloSegConfig};
    use burn::module::ModuleVisitor;
    use burn::tensor::Device;

    /// Collects (path, values) of the trainable float parameters.
    struct Paths {
        stack: Vec<String>,
        out: Vec<(String, Vec<f32>)>,
    }
    impl ModuleVisitor for Paths {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.stack.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.stack.pop();
        }
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            let v = p.val().into_data().try_to_vec::<f32>().unwrap();
            self.out.push((self.stack.join("."), v));
        }
    }

    fn tiny_model(dev: &Device) -> crate::model::yolo::YoloSeg {
        YoloSegConfig::new(Scale::N, 1)
            .with_input_size(32)
            .with_width_mult(0.25)
            .with_num_masks(4)
            .init(dev)
    }

    /// With zero gradients, SGD weight decay alone moves the weights: conv weights must
    /// shrink, BatchNorm γ/β and biases must not.
    #[test]
    fn no_weight_decay_on_biases_and_norms() {
        let dev = Device::flex().autodiff();
        let model = tiny_model(&dev);
        let mut t = TrainConfig::default();
        t.weight_decay = 0.5;
        t.momentum = 0.0;
        let mut opt = build(&t);
        let out = model.forward(burn::tensor::Tensor::zeros([1, 3, 32, 32], &dev));
        let zero =
            (out.cls_logits.sum() + out.proto.sum() + out.box_dist.sum() + out.mask_coef.sum())
                .mul_scalar(0.0);
        let grads = GradientsParams::from_grads(zero.backward(), &model);
        let mut before = Paths {
            stack: vec![],
            out: vec![],
        };
        model.valid().visit(&mut before);
        let after_model = opt.step(1.0, model, grads);
        let mut after = Paths {
            stack: vec![],
            out: vec![],
        };
        after_model.valid().visit(&mut after);
        let (mut decayed, mut kept) = (0, 0);
        for ((path, a), (_, b)) in before.out.iter().zip(&after.out) {
            let moved = a
                .iter()
                .zip(b)
                .any(|(x, y)| (x - y).abs() > 1e-7 && *x != 0.0);
            let exempt =
                path.ends_with("gamma") || path.ends_with("beta") || path.ends_with("bias");
            if path.ends_with("running_mean") || path.ends_with("running_var") {
                continue;
            }
            if exempt {
                assert!(!moved, "{path} was decayed");
                kept += 1;
            } else if path.ends_with("weight") && a.iter().any(|x| *x != 0.0) {
                assert!(moved, "{path} was not decayed");
                decayed += 1;
            }
        }
        assert!(
            decayed > 10 && kept > 10,
            "{decayed} decayed, {kept} exempt"
        );
    }

    #[test]
    fn global_norm_clipping_scales_all_grads() {
        let dev = Device::flex().autodiff();
        let model = tiny_model(&dev);
        let out = model.forward(burn::tensor::Tensor::ones([1, 3, 32, 32], &dev));
        let loss = out.cls_logits.sum().mul_scalar(100.0) + out.proto.powi_scalar(2).sum();
        let mut grads = GradientsParams::from_grads(loss.backward(), &model);
        let n0 = grad_norm(&model, &grads);
        assert!(n0 > 1.0, "{n0}");
        let r = clip_global_norm(&model, &mut grads, 1.0).unwrap();
        assert!((r - n0).abs() < 1e-9);
        let n1 = grad_norm(&model, &grads);
        assert!((n1 - 1.0).abs() < 1e-3, "clipped norm {n1}");
        // Below the threshold nothing changes.
        assert!((clip_global_norm(&model, &mut grads, 10.0).unwrap() - n1).abs() < 1e-9);
        assert!((grad_norm(&model, &grads) - n1).abs() < 1e-6);
    }

    /// The per-group learning rate of warmup reaches the right parameters: with rate 0
    /// for weights and 1 for the bias group, only biases and BatchNorm β move.
    #[test]
    fn bias_group_gets_its_own_learning_rate() {
        use burn::optim::lr_scheduler::module_lr_scheduler::ModuleLrScheduler;
        let dev = Device::flex().autodiff();
        let model = tiny_model(&dev);
        let mut t = TrainConfig::default();
        t.weight_decay = 0.0;
        t.momentum = 0.0;
        let mut opt = build(&t);
        let out = model.forward(burn::tensor::Tensor::ones([1, 3, 32, 32], &dev));
        let loss = out.cls_logits.sum() + out.proto.sum() + out.box_dist.sum();
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        let mut before = Paths {
            stack: vec![],
            out: vec![],
        };
        model.valid().visit(&mut before);
        let group = ParamGroup::from_regex(crate::train::schedule::BIAS).unwrap();
        let rates = ModuleLrScheduler::new(0.0).with_group(group, 1.0).step();
        let after_model = opt.step(rates, model, grads);
        let mut after = Paths {
            stack: vec![],
            out: vec![],
        };
        after_model.valid().visit(&mut after);
        let (mut biases, mut weights) = (0, 0);
        for ((path, a), (_, b)) in before.out.iter().zip(&after.out) {
            let moved = a.iter().zip(b).any(|(x, y)| (x - y).abs() > 1e-7);
            if path.ends_with("bias") || path.ends_with("beta") {
                biases += moved as usize;
            } else if path.ends_with("weight") || path.ends_with("gamma") {
                assert!(!moved, "{path} moved at learning rate 0");
                weights += 1;
            }
        }
        assert!(
            biases > 10 && weights > 10,
            "{biases} biases moved, {weights} weights"
        );
    }
}
