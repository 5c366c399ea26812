//! COCO instances JSON → parse + validate: errors, never panics; a file that validates
//! rasterises every segmentation to a mask of its image's size.
#![no_main]

use chicktrain::annotations::coco::CocoDataset;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(ds) = CocoDataset::from_json(text) {
        for a in &ds.annotations {
            let im = ds.image(a.image_id).expect("validated image id");
            // Rasterising is only cheap for small images.
            if (im.height as u64) * (im.width as u64) <= 1 << 16 {
                let rle = a.segmentation.to_rle(im.height, im.width).expect("validated segmentation");
                assert_eq!(rle.decode().data.len() as u64, im.height as u64 * im.width as u64);
            }
        }
    }
});
