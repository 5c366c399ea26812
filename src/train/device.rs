//! The Burn device of a config's `device` key.

use burn::tensor::Device;

use crate::config::DeviceKind;

/// The Burn device of a kind.
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
pub fn device_of(kind: DeviceKind) -> Device {
    match kind {
        DeviceKind::Flex => Device::flex(),
        DeviceKind::Ndarray => Device::ndarray(),
    }
}
