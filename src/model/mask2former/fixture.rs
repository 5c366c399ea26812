//! Readers of the PyTorch reference fixtures (`tests/fixtures/mask2former/`) the unit
//! tests of the matcher, criterion and masked attention share (test builds only). Its own
//! file so those tests do not import the model's `mod.rs`.

use serde_json::Value;

/// A JSON array of numbers as f32.
pub fn vecf(v: &Value) -> Vec<f32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect()
}

/// The point-sampling, loss and matcher reference (`points_losses.json`).
pub fn points_losses() -> Value {
    serde_json::from_str(include_str!(
        "../../../tests/fixtures/mask2former/points_losses.json"
    ))
    .unwrap()
}
