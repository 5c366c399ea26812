//! Reduced-precision training (`train.precision`): the float type of the run's device and
//! the casts at its boundaries.
//!
//! Burn has no autocast, so "bf16" / "f16" make the reduced type the device's default
//! float type ([`configure`]): activations, their gradients and every tensor built from
//! host f32 data (images, targets) live in it. The trainable weights are f32 masters, as
//! in torch AMP: each step runs forward on a copy cast inside the autodiff graph
//! ([`graph_cast`]), so backward delivers f32 gradients to the masters and the optimiser
//! (and its state) works in f32; an update smaller than a reduced weight's rounding step
//! (2⁻⁸ relative in bf16) is not lost. Also f32: the EMA copy, every checkpoint section of
//! weights ([`cast_module`] on save, cast to the run's type on load), gradient and
//! weight norms (summed in f32: f16 squares overflow), and every host read
//! (`util::tensor`). BatchNorm running statistics are buffers the forward updates, so
//! they live in the run's type. The f32 path casts nothing (a cast to a tensor's own type
//! is the tensor, and the trainer skips the per-step copy).

use anyhow::{bail, Result};
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Device, FloatDType, Tensor};

use crate::config::{DeviceKind, Precision};

/// The Burn float type of a precision.
pub fn float_dtype(p: Precision) -> FloatDType {
    match p {
        Precision::F32 => FloatDType::F32,
        Precision::F16 => FloatDType::F16,
        Precision::Bf16 => FloatDType::BF16,
    }
}

/// Makes `p` the default float type of `device` (`kind` names it in messages). Must run
/// before any tensor exists there: settings are fixed per device and process once a
/// tensor has been made. f32 changes nothing (the backends' default) but is refused on a
/// device an earlier run in this process set to another type (a sweep of precisions in
/// one process would otherwise train its "f32" runs in that type).
pub fn configure(device: &mut Device, kind: DeviceKind, p: Precision) -> Result<()> {
    if p == Precision::F32 {
        let have = device.settings().float_dtype;
        if have != FloatDType::F32 {
            bail!(
                "train.precision = \"f32\": device {kind:?} already computes in {have:?} in this process (an earlier run in it set that); run f32 as its own chicktrain command"
            );
        }
        return Ok(());
    }
    let want = float_dtype(p);
    if !device.supports_dtype(want) {
        bail!(
            "train.precision = \"{}\": device {kind:?} has no {want:?} support; use train.precision = \"f32\" there, or --device flex (CPU, f16 and bf16) or a GPU",
            p.name()
        );
    }
    if let Err(e) = device.configure(want) {
        if device.settings().float_dtype == want {
            return Ok(());
        }
        bail!(
            "train.precision = \"{}\": cannot set device {kind:?} to {want:?} ({e:?}): this process already made tensors there in {:?}; the precision is fixed per process, so run the other precision as its own chicktrain command",
            p.name(),
            device.settings().float_dtype
        );
    }
    Ok(())
}

/// Whether every float tensor of `m` is in `dtype` (true for a module without any).
pub fn all_in<M: Module>(m: &M, dtype: FloatDType) -> bool {
    struct Check(FloatDType, bool);
    impl ModuleVisitor for Check {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.1 &= FloatDType::from(p.val().dtype()) == self.0;
        }
    }
    let mut c = Check(dtype, true);
    m.visit(&mut c);
    c.1
}

/// Casts every float tensor; a trainable one stays a trainable leaf (not a node behind
/// a cast, which would take no gradient of its own).
struct CastFloats(FloatDType);

impl ModuleMapper for CastFloats {
    fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let dt = self.0;
        p.map(|t| {
            if FloatDType::from(t.dtype()) == dt {
                return t;
            }
            let grad = t.is_require_grad();
            let c = t.cast(dt).detach();
            if grad {
                c.require_grad()
            } else {
                c
            }
        })
    }
}

/// Casts every float tensor as an operation of the autodiff graph: the cast copy's
/// gradients flow back, cast, to the source's tensors.
struct CastInGraph(FloatDType);

impl ModuleMapper for CastInGraph {
    fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let dt = self.0;
        p.map(|t| t.cast(dt))
    }
}

/// The forward copy of f32 master weights `m` in the run's `dtype`: backward of a loss
/// computed with it gives gradients (in f32) to `m`'s parameters, same ids. Casts the
/// shared BatchNorm running statistics in place (once; they then stay in `dtype`).
pub fn graph_cast<M: Module>(m: M, dtype: FloatDType) -> M {
    m.map(&mut CastInGraph(dtype))
}

/// `m` with every float tensor in `dtype`; `m` itself when it already is (the f32 path:
/// untouched). BatchNorm running statistics are cast in place (Burn shares them between
/// clones), so cast a copy made by `valid()` (which has its own) when the source must
/// stay as it is.
pub fn cast_module<M: Module>(m: M, dtype: FloatDType) -> M {
    if all_in(&m, dtype) {
        m
    } else {
        m.map(&mut CastFloats(dtype))
    }
}

/// `m` in `dtype` for use on the run's device (evaluation of the f32 EMA): a clone when
/// it already is, else a cast of a `valid()` copy (so `m`'s shared running statistics
/// are not cast in place).
pub fn copy_in<M: Module>(m: &M, dtype: FloatDType) -> M {
    if all_in(m, dtype) {
        m.clone()
    } else {
        cast_module(m.valid(), dtype)
    }
}

/// A detached copy of `m` in f32 (for checkpoints and the EMA); a plain `valid()` copy
/// when `m` already is f32.
pub fn f32_copy<M: Module>(m: &M) -> M {
    cast_module(m.valid(), FloatDType::F32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_graph_cast_copy_gives_f32_gradients_to_the_f32_masters() {
        use burn::nn::{Linear, LinearConfig};
        use burn::optim::GradientsParams;
        let ad = Device::flex().autodiff();
        let master: Linear = LinearConfig::new(4, 3).init(&ad);
        let fwd = graph_cast(master.clone(), FloatDType::BF16);
        assert!(all_in(&fwd, FloatDType::BF16) && all_in(&master, FloatDType::F32));
        let x = Tensor::<2>::ones([2, 4], &ad).cast(FloatDType::BF16);
        let loss = fwd.forward(x).powi_scalar(2).sum();
        assert_eq!(FloatDType::from(loss.dtype()), FloatDType::BF16);
        let grads = GradientsParams::from_grads(loss.backward(), &master);
        let g = grads
            .get::<2>(master.weight.id)
            .expect("the master weight has a gradient");
        assert_eq!(FloatDType::from(g.dtype()), FloatDType::F32);
        let v = crate::util::tensor::to_host(g);
        assert!(
            v.iter().all(|x| x.is_finite()) && v.iter().any(|x| *x != 0.0),
            "{v:?}"
        );
    }

    #[test]
    fn ndarray_refuses_reduced_precision_with_a_message() {
        // burn-ndarray has no f16 / bf16 kernels (its dtype_usage is empty for them).
        for p in [Precision::Bf16, Precision::F16] {
            #[allow(deprecated)]
            let mut d = Device::ndarray();
            let e = configure(&mut d, DeviceKind::Ndarray, p)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!("train.precision = \"{}\"", p.name()))
                    && e.contains("no ")
                    && e.contains("--device flex"),
                "{e}"
            );
        }
        // f32 never touches the device.
        configure(&mut Device::flex(), DeviceKind::Flex, Precision::F32).unwrap();
    }
}
