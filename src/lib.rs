//! chicktrain library: data layer and the built-in renderer.
pub mod data;
pub mod render;
