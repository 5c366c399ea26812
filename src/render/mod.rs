//! Built-in renderer.
pub mod carcass;
pub mod glb;
pub mod mesh;
