//! Progress bars (indicatif; they draw nothing when stderr is not a terminal, so CI logs
//! only get the plain per-epoch lines the trainer prints).

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps labelled `what`, with throughput and ETA.
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(&format!(
            "{what:>10} {{bar:30}} {{pos}}/{{len}} {{msg}} {{per_sec}} eta {{eta}}"
        ))
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b
}
