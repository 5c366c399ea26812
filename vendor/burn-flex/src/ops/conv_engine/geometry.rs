//! The shape of one 2D convolution as the engine sees it, and how its output
//! rows are cut into tiles.
//!
//! Kept apart from the kernels so that forward, input-gradient and
//! weight-gradient passes agree on one tiling: a tile is a run of whole output
//! rows, so every tile is a contiguous column range of the `[c_out, oh * ow]`
//! output plane and the GEMMs can read and write NCHW tensors in place.

use burn_backend::ops::ConvOptions;
use burn_backend::ops::conv::calculate_conv_output_size;

/// Target number of output pixels (GEMM columns) per tile. The im2col panel of
/// a tile holds `k() * tile_cols` elements; 512 columns keeps the panels of
/// YOLO-sized layers (K ≤ 9 · 256) in L2 and is the old path's tile size too.
const TILE_COLS: usize = 512;

/// Geometry of a grouped 2D convolution over NCHW tensors with symmetric padding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Geometry {
    pub batch: usize,
    pub c_in: usize,
    pub h: usize,
    pub w: usize,
    pub c_out: usize,
    pub groups: usize,
    /// Input channels per group (`weight.shape[1]`).
    pub cpg: usize,
    /// Output channels per group.
    pub mpg: usize,
    pub kh: usize,
    pub kw: usize,
    pub sh: usize,
    pub sw: usize,
    pub ph: usize,
    pub pw: usize,
    pub dh: usize,
    pub dw: usize,
    pub oh: usize,
    pub ow: usize,
}

impl Geometry {
    /// Geometry of `x` `[b, c_in, h, w]` convolved with `weight`
    /// `[c_out, c_in / groups, kh, kw]`; `None` when the engine does not take
    /// the shape (asymmetric padding, inconsistent channels, empty output).
    pub fn new(x: &[usize], weight: &[usize], options: &ConvOptions<2>) -> Option<Self> {
        if x.len() != 4 || weight.len() != 4 || options.is_asymmetric() {
            return None;
        }
        let groups = options.groups;
        let (c_in, c_out, cpg) = (x[1], weight[0], weight[1]);
        if groups == 0 || cpg * groups != c_in || c_out % groups != 0 || c_out == 0 {
            return None;
        }
        let [ph, pw] = options.padding_begin();
        let [sh, sw] = options.stride;
        let [dh, dw] = options.dilation;
        let (kh, kw) = (weight[2], weight[3]);
        // Reject kernels larger than the padded input before the output-size
        // formula (which would underflow) sees them.
        if kh == 0 || kw == 0 || sh == 0 || sw == 0 || dh == 0 || dw == 0 {
            return None;
        }
        if dh * (kh - 1) + 1 > x[2] + 2 * ph || dw * (kw - 1) + 1 > x[3] + 2 * pw {
            return None;
        }
        let oh = calculate_conv_output_size(kh, sh, ph, dh, x[2]);
        let ow = calculate_conv_output_size(kw, sw, pw, dw, x[3]);
        if oh == 0 || ow == 0 || x[0] == 0 {
            return None;
        }
        Some(Self {
            batch: x[0],
            c_in,
            h: x[2],
            w: x[3],
            c_out,
            groups,
            cpg,
            mpg: c_out / groups,
            kh,
            kw,
            sh,
            sw,
            ph,
            pw,
            dh,
            dw,
            oh,
            ow,
        })
    }

    /// GEMM depth of one group: rows of the im2col panel, `cpg * kh * kw`, in
    /// the order of the weight's `[cpg, kh, kw]` dimensions, so the weight is
    /// used as the GEMM's left matrix without repacking.
    pub fn k(&self) -> usize {
        self.cpg * self.kh * self.kw
    }

    pub fn in_plane(&self) -> usize {
        self.h * self.w
    }

    pub fn out_plane(&self) -> usize {
        self.oh * self.ow
    }

    /// A 1×1, stride-1, unpadded convolution: the NCHW input already is the
    /// GEMM's right matrix, no panel is needed.
    pub fn is_pointwise(&self) -> bool {
        self.kh == 1 && self.kw == 1 && self.sh == 1 && self.sw == 1 && self.ph == 0 && self.pw == 0
    }

    /// Every input channel has its own filter (`groups == c_in`, one channel per group).
    pub fn is_depthwise(&self) -> bool {
        self.cpg == 1 && self.groups == self.c_in && self.groups > 1
    }

    /// Output rows per tile: about [`TILE_COLS`] columns, but small enough
    /// that there are at least two tiles per worker thread when the batch is
    /// smaller than that (batch-1 inference must still use every core).
    pub fn rows_per_tile(&self, threads: usize) -> usize {
        rows_per_task(self.oh, self.ow, TILE_COLS, self.batch, threads)
    }

    /// The tiles as `(first_row, end_row)` half-open ranges of output rows.
    pub fn tiles(&self, threads: usize) -> alloc::vec::Vec<(usize, usize)> {
        let rows = self.rows_per_tile(threads);
        (0..self.oh)
            .step_by(rows)
            .map(|r0| (r0, (r0 + rows).min(self.oh)))
            .collect()
    }

    /// Output columns `[lo, hi)` whose input column `o * sw + j * dw - pw`
    /// for kernel column `j` lies inside the image; outside it is padding.
    pub fn valid_cols(&self, j: usize) -> (usize, usize) {
        let off = j * self.dw;
        let lo = if self.pw > off {
            (self.pw - off).div_ceil(self.sw)
        } else {
            0
        };
        let hi = if self.w + self.pw > off {
            (self.w + self.pw - off).div_ceil(self.sw)
        } else {
            0
        };
        let hi = hi.min(self.ow);
        (lo.min(hi), hi)
    }

    /// Input row read by output row `r` and kernel row `i`, if inside the image.
    pub fn input_row(&self, r: usize, i: usize) -> Option<usize> {
        let ih = (r * self.sh + i * self.dh).checked_sub(self.ph)?;
        (ih < self.h).then_some(ih)
    }
}

/// Rows per task when each of `batch` images has `rows` rows of `row_len`
/// columns to cut into tasks of about `target` columns: at least one row, and
/// few enough rows that there are at least two tasks per worker thread when
/// the batch alone does not give that many (batch-1 inference must still use
/// every core). The engine's tiles and Winograd's tile-row runs both use it.
pub(crate) fn rows_per_task(
    rows: usize,
    row_len: usize,
    target: usize,
    batch: usize,
    threads: usize,
) -> usize {
    let mut per_task = (target / row_len).clamp(1, rows);
    let want = (2 * threads).div_ceil(batch);
    if rows.div_ceil(per_task) < want {
        per_task = rows.div_ceil(want).max(1);
    }
    per_task
}
