//! Pickles as found in a `.pt` file's `data.pkl` → values: never panics, never overflows the
//! stack; a module found in the result walks to a state dict or an error.
#![no_main]

use chicktrain::weights::pickle::unpickle;
use chicktrain::weights::torch_module::{module_state_dict, tensor_dict};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(v) = unpickle(data) {
        if v.is_module() {
            let _ = module_state_dict(&v);
        }
        let _ = tensor_dict(&v);
        for key in ["ema", "model", "state_dict"] {
            if let Some(m) = v.get(key) {
                if m.is_module() {
                    let _ = module_state_dict(&m);
                }
            }
        }
    }
});
