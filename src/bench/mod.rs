//! Speed / accuracy measurements built on the rest of the crate: model variants × input
//! sizes ([`models`]: parameters, GFLOPs, latency, training throughput, peak memory,
//! checkpoint AP), the scene ablation ([`ablation`]), the randomisation / augmentation
//! ablation scored on an external set ([`transfer`]), flex vs tract inference latency
//! ([`engines`]) and the training loader's rate alone ([`loader`]). Their parts: variant names
//! ([`variant`]), one row's measurement ([`measure`]) in a fresh child process
//! ([`worker`]), test AP of trained models ([`accuracy`]) and the CSV / markdown / PNG
//! report ([`report`]), which goes through [`crate::eval::report`] and
//! [`crate::eval::plots`]. The paper's synthetic-data sweep is
//! [`crate::experiments::sweep`].

pub mod ablation;
pub mod accuracy;
pub mod engines;
pub mod loader;
pub mod measure;
pub mod models;
pub mod report;
pub mod transfer;
pub mod variant;
pub mod worker;
