//! Exponential moving average of the weights (ultralytics `ModelEMA`): after every
//! optimiser step, `ema = d·ema + (1 − d)·model` over every float tensor, BatchNorm running
//! statistics included, with `d = 0.9999·(1 − exp(−updates / 2000))` so early updates
//! follow the model closely. The EMA copy lives on the plain (non-autodiff) device in eval
//! mode; it is what the trainer evaluates and saves in `best.bpk`. Tensors of frozen stages
//! (`train.freeze`) are not blended: they equal the model's and stay bit-identical (a blend
//! of two equal values can round away from them).

use std::collections::VecDeque;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{FloatDType, Tensor};

/// Decay and ramp of ultralytics' `ModelEMA`.
pub const DECAY: f64 = 0.9999;
pub const TAU: f64 = 2000.0;

pub struct Ema<M> {
    pub model: M,
    pub updates: u64,
    /// Module-path prefixes of frozen stages (`model::freeze`), left as they are.
    pub frozen: Vec<String>,
}

/// Every float tensor of a module, flattened, in visiting order.
struct Collect(VecDeque<Tensor<1>>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        // f32: the EMA of a reduced-precision run is kept in f32 (a no-op cast on the
        // f32 path).
        let t = param.val().cast(FloatDType::F32);
        let n = t.shape().num_elements();
        self.0.push_back(t.reshape([n]));
    }
}

/// Blends the collected tensors into a module of the same structure, matched by visiting
/// order. Not by `ParamId`: a checkpoint restores the ids of weights but gives BatchNorm
/// running statistics fresh ones, so after `--resume` an id match silently froze the
/// EMA's running statistics (found by `tests/resume.rs`).
struct Blend<'a> {
    src: VecDeque<Tensor<1>>,
    d: f64,
    path: crate::model::freeze::StagePath,
    frozen: &'a [String],
}

impl ModuleMapper for Blend<'_> {
    fn enter_module(&mut self, name: &str, container: &str) {
        self.path.enter(name, container);
    }
    fn exit_module(&mut self, _: &str, container: &str) {
        self.path.exit(container);
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let s = self
            .src
            .pop_front()
            .expect("Ema: the model has fewer tensors than its EMA copy");
        if self.path.frozen(self.frozen) {
            return param;
        }
        let d = self.d;
        param.map(|e| {
            let dims = e.dims();
            assert_eq!(
                s.dims()[0],
                dims.iter().product::<usize>(),
                "Ema: model and EMA copy differ in structure"
            );
            e.mul_scalar(d) + s.reshape(dims).mul_scalar(1.0 - d)
        })
    }
}

impl<M: Module> Ema<M> {
    /// Starts from a copy of `model` (eval mode, plain device), in f32 whatever the
    /// run's precision.
    pub fn new(model: &M, updates: u64) -> Ema<M> {
        Ema {
            model: crate::infer::precision::f32_copy(model),
            updates,
            frozen: Vec::new(),
        }
    }

    /// Leaves the tensors under `prefixes` (frozen stages) out of every blend.
    pub fn with_frozen(mut self, prefixes: Vec<String>) -> Self {
        self.frozen = prefixes;
        self
    }

    /// Decay used by the next update.
    pub fn decay(updates: u64) -> f64 {
        DECAY * (1.0 - (-(updates as f64) / TAU).exp())
    }

    /// Blends the current training weights in.
    pub fn update(&mut self, model: &M) {
        self.updates += 1;
        let d = Self::decay(self.updates);
        let mut c = Collect(VecDeque::new());
        model.valid().visit(&mut c);
        let m = self.model.clone();
        self.model = m.map(&mut Blend {
            src: c.0,
            d,
            path: Default::default(),
            frozen: &self.frozen,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::yolo::{Scale, YoloSeg, YoloSegConfig};
    use burn::tensor::Device;

    fn first_weight(m: &YoloSeg) -> Vec<f32> {
        struct First(Option<Vec<f32>>);
        impl ModuleVisitor for First {
            fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
                if self.0.is_none() {
                    self.0 = Some(p.val().into_data().try_to_vec::<f32>().unwrap());
                }
            }
        }
        let mut f = First(None);
        m.visit(&mut f);
        f.0.unwrap()
    }

    #[test]
    fn update_blends_with_the_ramped_decay() {
        type E = Ema<YoloSeg>;
        assert!(E::decay(1) < 0.001);
        assert!((E::decay(1_000_000) - DECAY).abs() < 1e-9);
        let dev = Device::flex();
        let cfg = YoloSegConfig::new(Scale::N, 1)
            .with_input_size(32)
            .with_width_mult(0.25)
            .with_num_masks(4);
        dev.seed(1);
        let a = cfg.init(&dev);
        let mut ema = Ema::new(&a, 2999);
        let e0 = first_weight(&ema.model);
        // The trained model moves: a copy of `a` with every weight doubled.
        struct Double;
        impl ModuleMapper for Double {
            fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
                p.map(|t| t.mul_scalar(2.0))
            }
        }
        let b = a.clone().map(&mut Double);
        ema.update(&b);
        assert_eq!(ema.updates, 3000);
        let d = E::decay(3000) as f32;
        for (e, x) in first_weight(&ema.model).iter().zip(&e0) {
            let want = d * x + (1.0 - d) * 2.0 * x;
            assert!(
                (e - want).abs() <= 1e-5 * want.abs().max(1.0),
                "{e} vs {want}"
            );
        }
    }
}
