//! safetensors bytes → tensors: never panics; what parses writes back and parses to the
//! same tensors.
#![no_main]

use chicktrain::weights::safetensors::{parse, to_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok((tensors, meta)) = parse(data) {
        let list: Vec<_> = tensors.into_iter().collect();
        let bytes = to_bytes(&list, &meta).expect("parsed tensors write back");
        let (back, meta2) = parse(&bytes).expect("written file parses");
        assert_eq!(meta2, meta);
        let again: Vec<_> = back.into_iter().collect();
        assert_eq!(again.len(), list.len());
        for ((k, a), (k2, b)) in list.iter().zip(&again) {
            assert_eq!(k, k2);
            assert_eq!(a.shape, b.shape);
        }
    }
});
