//! Speed / accuracy measurements built on the rest of the crate: model variants × input
//! sizes ([`models`]: parameters, GFLOPs, latency, training throughput, peak memory,
//! checkpoint AP), the scene ablation ([`ablation`]) and the synthetic-data sweep of the
//! paper's Table 2 ([`sweep`]). Reports go through [`crate::eval::report`] and
//! [`crate::eval::plots`].

pub mod ablation;
pub mod models;
