//! The JSON fixtures under `tests/fixtures/` (reference numbers written by the scripts
//! beside them): reading one, and its arrays of numbers as `f32`.

use serde_json::Value;

/// `tests/fixtures/<rel>`, parsed.
pub fn fixture(rel: &str) -> Value {
    let path = format!("{}/tests/fixtures/{rel}", env!("CARGO_MANIFEST_DIR"));
    serde_json::from_str(&std::fs::read_to_string(&path).expect(&path)).unwrap()
}

/// The numbers of a (nested) JSON array, in order, as `f32`.
pub fn floats(v: &Value) -> Vec<f32> {
    fn flat(v: &Value, out: &mut Vec<f32>) {
        match v {
            Value::Array(a) => a.iter().for_each(|x| flat(x, out)),
            Value::Number(n) => out.push(n.as_f64().unwrap() as f32),
            other => panic!("unexpected {other}"),
        }
    }
    let mut out = Vec::new();
    flat(v, &mut out);
    out
}
