//! chicktrain library: everything the binary does lives here so that `tests/` can reach it.
//!
//! This branch (`yolo`) adds only [`model`]; the lead reconciles the other modules at merge.

pub mod model;
