//! COCO compressed RLE strings → counts: never panics; what decodes re-encodes to the
//! same counts, and its area and box stay inside the image.
#![no_main]

use chicktrain::data::rle::Rle;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    // First two bytes: the image size (small, so decoding stays cheap).
    let (h, w) = (data[0] as u32 % 64, data[1] as u32 % 64);
    let Ok(s) = std::str::from_utf8(&data[2..]) else {
        return;
    };
    if let Ok(rle) = Rle::from_compressed(s, h, w) {
        assert!(rle.area() <= (h * w) as u64);
        let back = Rle::from_compressed(&rle.to_compressed(), h, w).expect("re-encoded RLE");
        assert_eq!(back, rle);
        let m = rle.decode();
        assert_eq!(m.area(), rle.area());
        let b = rle.bbox();
        assert!(b[0] >= 0.0 && b[1] >= 0.0 && b[0] + b[2] <= w as f64 && b[1] + b[3] <= h as f64);
    }
});
