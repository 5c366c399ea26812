//! Speed / accuracy measurements built on the rest of the crate: model variants × input
//! sizes ([`models`]: parameters, GFLOPs, latency, training throughput, peak memory,
//! checkpoint AP), flex vs tract inference latency ([`engines`]) and the training loader's
//! rate alone ([`loader`]). Their parts: variant names ([`variant`]), one row's measurement
//! ([`measure`]) in a fresh child process ([`worker`]), test AP of trained models
//! ([`accuracy`]), the effort flags ([`effort`]) and the CSV / markdown / PNG report ([`report`]), which goes through
//! [`crate::eval::report`] and [`crate::eval::plots`]. The studies that train (the
//! synthetic-data sweep, the scene and transfer ablations) are in `experiments/`, which
//! times its ablation through these parts.

pub mod accuracy;
pub mod effort;
pub mod engines;
pub mod loader;
pub mod measure;
pub mod models;
pub mod report;
pub mod variant;
pub mod worker;
