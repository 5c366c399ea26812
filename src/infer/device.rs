//! The Burn device of a config's `device` key. GPU backends are cargo features (`cuda`,
//! `wgpu`); a device the binary was not built for, or a GPU that is not there, is an
//! error that says what to do — never a panic in the middle of a run.

use anyhow::{bail, Result};
use burn::tensor::Device;

use crate::config::{DeviceKind, Precision};

use super::precision::configure;

/// The Burn device of a kind in its float type as it is (f32, unless a run in this
/// process set another), checked to work like [`device_with`]: evaluation, prediction
/// and benchmarks, which load f32 checkpoints into whatever type the device has.
pub fn device_of(kind: DeviceKind) -> Result<Device> {
    build(kind, None)
}

/// The Burn device of a kind with default float type `p` (`train.precision`, set before
/// any tensor exists there), checked to work: a GPU device runs one small operation
/// first, so a missing driver or GPU fails here with a message rather than as a panic
/// at the first training step.
pub fn device_with(kind: DeviceKind, p: Precision) -> Result<Device> {
    build(kind, Some(p))
}

#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn build(kind: DeviceKind, p: Option<Precision>) -> Result<Device> {
    match kind {
        DeviceKind::Flex | DeviceKind::Ndarray => {
            let mut d = match kind {
                DeviceKind::Flex => Device::flex(),
                _ => Device::ndarray(),
            };
            if let Some(p) = p {
                configure(&mut d, kind, p)?;
            }
            Ok(d)
        }
        DeviceKind::Cuda(index) => cuda(index, p),
        DeviceKind::Wgpu => wgpu(p),
    }
}

#[cfg(feature = "cuda")]
fn cuda(index: usize, p: Option<Precision>) -> Result<Device> {
    probe(
        || Device::cuda(index),
        DeviceKind::Cuda(index),
        p,
        &format!("cuda:{index}"),
        "an NVIDIA driver (nvidia-smi lists the GPU) and the CUDA runtime libraries",
    )
}

#[cfg(not(feature = "cuda"))]
fn cuda(index: usize, _: Option<Precision>) -> Result<Device> {
    bail!(
        "device cuda:{index}: this chicktrain was built without the `cuda` feature; build it with `cargo build --release --features cuda` (running it needs an NVIDIA driver and the CUDA runtime libraries), or use --device flex"
    )
}

#[cfg(feature = "wgpu")]
fn wgpu(p: Option<Precision>) -> Result<Device> {
    probe(
        || Device::wgpu(burn::tensor::DeviceKind::DefaultDevice),
        DeviceKind::Wgpu,
        p,
        "wgpu",
        "a Vulkan, Metal or DX12 driver (on Linux e.g. `vulkaninfo` lists a device)",
    )
}

#[cfg(not(feature = "wgpu"))]
fn wgpu(_: Option<Precision>) -> Result<Device> {
    bail!(
        "device wgpu: this chicktrain was built without the `wgpu` feature; build it with `cargo build --release --features wgpu` (running it needs a Vulkan, Metal or DX12 driver), or use --device flex"
    )
}

/// Builds the device, sets its float type `p` (if given) and runs `1 + 1` on it with the
/// panic hook silenced: backends panic when no adapter or driver is found, which becomes
/// an error naming `needs`.
#[cfg(any(feature = "cuda", feature = "wgpu"))]
fn probe(
    make: impl FnOnce() -> Device,
    kind: DeviceKind,
    p: Option<Precision>,
    name: &str,
    needs: &str,
) -> Result<Device> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    // The probe's state is dropped on a panic, never observed half-updated.
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut d = make();
        p.map_or(Ok(()), |p| configure(&mut d, kind, p)).map(|()| {
            let one = burn::tensor::Tensor::<1>::ones([1], &d);
            let v = crate::util::tensor::to_host(one.clone() + one);
            (d, v)
        })
    }));
    std::panic::set_hook(hook);
    match r {
        Ok(Err(e)) => Err(e),
        Ok(Ok((d, v))) if v == [2.0] => Ok(d),
        Ok(Ok((_, v))) => bail!("device {name} computed 1 + 1 = {v:?}; its driver is broken"),
        Err(p) => {
            let why = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "no reason given".into());
            bail!("device {name} is not usable ({why}); it needs {needs}, or use --device flex")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_devices_work_and_missing_features_are_named() {
        for k in [DeviceKind::Flex, DeviceKind::Ndarray] {
            device_of(k).unwrap();
        }
        #[cfg(not(feature = "cuda"))]
        {
            let e = device_of(DeviceKind::Cuda(1)).unwrap_err().to_string();
            assert!(e.contains("cuda:1") && e.contains("--features cuda"), "{e}");
        }
        #[cfg(not(feature = "wgpu"))]
        {
            let e = device_of(DeviceKind::Wgpu).unwrap_err().to_string();
            assert!(e.contains("--features wgpu"), "{e}");
        }
    }
}
