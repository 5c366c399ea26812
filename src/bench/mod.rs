//! Speed / accuracy measurements built on the rest of the crate: model variants × input
//! sizes ([`models`]: parameters, GFLOPs, latency, training throughput, peak memory,
//! checkpoint AP), flex vs tract inference latency ([`engines`]), the training loader's
//! rate alone ([`loader`]) and flex's convolution engine against the path it replaces
//! ([`convs`], over the models' shapes in [`conv_shapes`], against the [`peak`] FLOP/s). Their parts: variant names ([`variant`]), one row's measurement
//! ([`measure`]) in a fresh child process ([`worker`]), test AP of trained models
//! ([`accuracy`]), the effort flags ([`effort`]) and the CSV / markdown / PNG report ([`report`]), which goes through
//! [`crate::eval::report`] and [`crate::eval::plots`]. The studies that train (the
//! synthetic-data sweep, the scene and transfer ablations) are in `experiments/`, which
//! times its ablation through these parts.

pub mod accuracy;
pub mod conv_shapes;
pub mod convs;
pub mod effort;
pub mod engines;
pub mod loader;
pub mod measure;
pub mod models;
pub mod peak;
pub mod report;
pub mod variant;
pub mod worker;
