//! The size of a built model (parameters, GFLOPs at its input size), printed at start
//! and reported by `bench models`.

/// Size of a model, printed at start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSummary {
    pub params: usize,
    /// 2 × multiply-accumulates of all convolutions (and attention matmuls) at `input` px.
    pub gflops: f64,
    pub input: usize,
}

impl std::fmt::Display for ModelSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.2} M parameters, {:.1} GFLOPs at {} px",
            self.params as f64 / 1e6,
            self.gflops,
            self.input
        )
    }
}
