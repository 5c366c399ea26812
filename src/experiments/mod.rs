//! Experiments built on the trainer: [`sweep`], the paper's synthetic-data experiment
//! (train each synthetic-image count with several seeds, report mean ± std).

pub mod sweep;
