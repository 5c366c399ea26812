//! The metadata of an exported YOLO-seg ONNX file: the keys ultralytics' `AutoBackend`
//! reads (`task`, `stride`, `imgsz`, `batch`, `names`, …), written as ultralytics writes
//! them (Python literals), and chicktrain's COCO category ids.

use crate::model::onnx::graph::OPSET;

/// The metadata ultralytics writes into its ONNX files (what its `AutoBackend` reads:
/// stride, task, names, imgsz …) and the COCO category ids of the classes, for a graph of
/// `batch` (symbolic with `dynamic`) at `[h, w]`.
pub fn metadata(
    names: &[String],
    category_ids: &[u64],
    (batch, dynamic): (usize, bool),
    strides: &[usize],
    [h, w]: [usize; 2],
) -> Vec<(String, String)> {
    let names = names
        .iter()
        .enumerate()
        .map(|(i, n)| format!("{i}: {}", py_str(n)))
        .collect::<Vec<_>>()
        .join(", ");
    let ids = category_ids
        .iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let py_bool = |b: bool| if b { "True" } else { "False" };
    vec![
        ("description".into(), "chicktrain YOLO11-seg model (ultralytics ONNX layout)".into()),
        ("author".into(), "chicktrain".into()),
        ("version".into(), env!("CARGO_PKG_VERSION").into()),
        ("stride".into(), strides.iter().max().copied().unwrap_or(32).to_string()),
        ("task".into(), "segment".into()),
        ("head".into(), "Segment".into()),
        ("batch".into(), batch.to_string()),
        ("imgsz".into(), format!("[{h}, {w}]")),
        ("names".into(), format!("{{{names}}}")),
        (
            "args".into(),
            format!(
                "{{'batch': {}, 'dynamic': {}, 'half': False, 'nms': False, 'opset': {OPSET}, 'simplify': False}}",
                batch,
                py_bool(dynamic)
            ),
        ),
        ("channels".into(), "3".into()),
        ("end2end".into(), "False".into()),
        ("chicktrain_category_ids".into(), format!("[{ids}]")),
    ]
}

/// Python literal of a string (single quotes, as `str(dict)` writes them).
fn py_str(s: &str) -> String {
    let mut o = String::from("'");
    for ch in s.chars() {
        match ch {
            '\\' => o.push_str("\\\\"),
            '\'' => o.push_str("\\'"),
            '\n' => o.push_str("\\n"),
            c => o.push(c),
        }
    }
    o.push('\'');
    o
}
