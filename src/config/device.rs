//! `device = "…"`: where a run's tensors live, as the string configs and checkpoints
//! write ([`DeviceKind`]); which backend each kind runs on is `infer::device`.

use serde::{Deserialize, Serialize};

/// Where a run's tensors live: `"flex"` (Burn's pure-Rust CPU backend, the default),
/// `"ndarray"` (the deprecated CPU backend, kept working), `"cuda"` / `"cuda:N"` (NVIDIA
/// GPU N, cargo feature `cuda`) or `"wgpu"` (the default wgpu adapter: Vulkan, Metal or
/// DX12; cargo feature `wgpu`). Written as that string in configs and checkpoints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeviceKind {
    Flex,
    Ndarray,
    Cuda(usize),
    Wgpu,
}

impl std::str::FromStr for DeviceKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<DeviceKind, String> {
        let bad = || format!("unknown device {s:?}: expected flex, ndarray, cuda, cuda:N or wgpu");
        Ok(match s.trim() {
            "flex" => DeviceKind::Flex,
            "ndarray" => DeviceKind::Ndarray,
            "cuda" => DeviceKind::Cuda(0),
            "wgpu" => DeviceKind::Wgpu,
            other => match other.strip_prefix("cuda:") {
                Some(n) => DeviceKind::Cuda(n.parse().map_err(|_| bad())?),
                None => return Err(bad()),
            },
        })
    }
}

impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeviceKind::Flex => write!(f, "flex"),
            DeviceKind::Ndarray => write!(f, "ndarray"),
            DeviceKind::Cuda(0) => write!(f, "cuda"),
            DeviceKind::Cuda(n) => write!(f, "cuda:{n}"),
            DeviceKind::Wgpu => write!(f, "wgpu"),
        }
    }
}

impl Serialize for DeviceKind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for DeviceKind {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}
