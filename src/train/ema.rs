//! Exponential moving average of the weights (ultralytics `ModelEMA`): after every
//! optimiser step, `ema = d·ema + (1 − d)·model` over every float tensor, BatchNorm running
//! statistics included, with `d = 0.9999·(1 − exp(−updates / 2000))` so early updates
//! follow the model closely. The EMA copy lives on the plain (non-autodiff) device in eval
//! mode; it is what the trainer evaluates and saves in `best.bpk`.

use std::collections::HashMap;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::tensor::Tensor;

use crate::model::yolo::YoloSeg;

/// Decay and ramp of ultralytics' `ModelEMA`.
pub const DECAY: f64 = 0.9999;
pub const TAU: f64 = 2000.0;

pub struct Ema {
    pub model: YoloSeg,
    pub updates: u64,
}

struct Collect(HashMap<ParamId, Tensor<1>>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let t = param.val();
        let n = t.shape().num_elements();
        self.0.insert(param.id, t.reshape([n]));
    }
}

struct Blend {
    src: HashMap<ParamId, Tensor<1>>,
    d: f64,
}

impl ModuleMapper for Blend {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let Some(s) = self.src.remove(&param.id) else {
            return param;
        };
        let d = self.d;
        param.map(|e| {
            let dims = e.dims();
            e.mul_scalar(d) + s.reshape(dims).mul_scalar(1.0 - d)
        })
    }
}

impl Ema {
    /// Starts from a copy of `model` (eval mode, plain device).
    pub fn new(model: &YoloSeg, updates: u64) -> Ema {
        Ema {
            model: model.valid(),
            updates,
        }
    }

    /// Decay used by the next update.
    pub fn decay(updates: u64) -> f64 {
        DECAY * (1.0 - (-(updates as f64) / TAU).exp())
    }

    /// Blends the current training weights in.
    pub fn update(&mut self, model: &YoloSeg) {
        self.updates += 1;
        let d = Self::decay(self.updates);
        let mut c = Collect(HashMap::new());
        model.valid().visit(&mut c);
        let m = self.model.clone();
        self.model = m.map(&mut Blend { src: c.0, d });
    }
}
