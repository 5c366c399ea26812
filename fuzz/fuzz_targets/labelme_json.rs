//! One LabelMe file → COCO: errors, never panics; what converts passes COCO validation.
#![no_main]

use std::path::Path;

use chicktrain::annotations::labelme;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Rasterising polygons costs the image's size: keep the fuzzer on small images.
    if let Ok(v) = serde_json::from_str::<serde_json::Value>(text) {
        let big = |k: &str| v[k].as_u64().is_some_and(|n| n > 512);
        if big("imageHeight") || big("imageWidth") {
            return;
        }
    }
    if let Ok(ds) = labelme::from_json(text, Path::new("/nonexistent/fuzz.json")) {
        ds.validate().expect("converted LabelMe validates");
    }
});
