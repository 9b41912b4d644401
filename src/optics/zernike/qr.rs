//! Incremental (blocked) Householder QR of a tall least-squares system that
//! is never stored whole.
//!
//! Rows of the augmented system `[A | b]` arrive one at a time and are
//! buffered in a small column-major block. When the block is full it is
//! annihilated against the current upper-triangular factor: the stack
//! `[R; B]` is re-factored by Householder reflections that touch only row c
//! of `R` and the block (everything below the diagonal of `R` is already
//! zero). After the last block `R` holds the triangular factor of `A` in its
//! top-left, `Q^T b` in its last column, and `|R[p, p]| = ||A x - b||`.

use nalgebra::{DMatrix, SVD};

/// Rows buffered per block. 256 rows x 232 columns of f64 is ~470 KiB, which
/// keeps a block in the L2 cache while each Householder column sweeps it.
pub(super) const BLOCK_ROWS: usize = 256;

/// Upper-triangular factor of `[A | b]`, updated block by block.
pub(super) struct IncrementalQr {
    /// Columns: unknowns + 1 (the right-hand side).
    cols: usize,
    /// Row-major `cols x cols`; only the upper triangle is meaningful.
    r: Vec<f64>,
    /// Column-major `BLOCK_ROWS x cols` row buffer.
    block: Vec<f64>,
    /// Rows currently buffered.
    rows: usize,
}

/// The finished factorisation.
pub(super) struct Factor {
    /// Unknowns p.
    pub p: usize,
    /// Row-major `(p+1) x (p+1)` upper-triangular factor of `[A | b]`.
    pub r: Vec<f64>,
}

impl IncrementalQr {
    /// An empty factorisation for `unknowns` coefficients.
    pub(super) fn new(unknowns: usize) -> Self {
        let cols = unknowns + 1;
        IncrementalQr {
            cols,
            r: vec![0.0; cols * cols],
            block: vec![0.0; BLOCK_ROWS * cols],
            rows: 0,
        }
    }

    /// Append one row `[a_1 .. a_p | b]` multiplied by `scale` (the square
    /// root of its weight). `row.len()` must be `unknowns + 1`.
    pub(super) fn push_row(&mut self, row: &[f64], scale: f64) {
        debug_assert_eq!(row.len(), self.cols);
        for (c, &v) in row.iter().enumerate() {
            self.block[c * BLOCK_ROWS + self.rows] = v * scale;
        }
        self.rows += 1;
        if self.rows == BLOCK_ROWS {
            self.flush();
        }
    }

    /// Fold the buffered rows into `r` and empty the buffer.
    fn flush(&mut self) {
        let (n, cols) = (self.rows, self.cols);
        for c in 0..cols {
            let (head, tail) = self.block.split_at_mut((c + 1) * BLOCK_ROWS);
            let v = &head[c * BLOCK_ROWS..c * BLOCK_ROWS + n];
            let sigma = dot(v, v);
            if sigma == 0.0 {
                continue; // block column already zero: nothing to annihilate
            }
            let rcc = self.r[c * cols + c];
            let norm = (rcc * rcc + sigma).sqrt();
            // Reflect [rcc; v] onto alpha e_c; the sign avoids cancellation in v0.
            let alpha = if rcc >= 0.0 { -norm } else { norm };
            let v0 = rcc - alpha;
            let beta = 1.0 / (norm * (norm + rcc.abs())); // 2 / ||[v0; v]||^2
            self.r[c * cols + c] = alpha;
            let r_row = &mut self.r[c * cols + c + 1..(c + 1) * cols];
            for (rcj, col) in r_row.iter_mut().zip(tail.chunks_exact_mut(BLOCK_ROWS)) {
                let col = &mut col[..n];
                let s = beta * (v0 * *rcj + dot(v, col));
                *rcj -= s * v0;
                axpy(-s, v, col);
            }
        }
        self.rows = 0;
    }

    /// Fold any buffered rows and return the factor.
    pub(super) fn finish(mut self) -> Factor {
        if self.rows > 0 {
            self.flush();
        }
        Factor {
            p: self.cols - 1,
            r: self.r,
        }
    }
}

impl Factor {
    /// `||A x - b||` at the least-squares solution.
    pub(super) fn residual_norm(&self) -> f64 {
        self.r[self.p * (self.p + 1) + self.p].abs()
    }

    /// 2-norm condition number of `A` (= that of its triangular factor), from
    /// the singular values of the p x p factor; infinite when singular or when
    /// the SVD does not converge, 1 for an empty system.
    pub(super) fn condition_number(&self) -> f64 {
        let (p, cols) = (self.p, self.p + 1);
        if p == 0 {
            return 1.0;
        }
        let m = DMatrix::from_fn(p, p, |i, j| if j >= i { self.r[i * cols + j] } else { 0.0 });
        let Some(svd) = SVD::try_new(m, false, false, f64::EPSILON, 10_000) else {
            return f64::INFINITY;
        };
        let s = &svd.singular_values;
        let (max, min) = (s.max(), s.min());
        if min > 0.0 && max.is_finite() {
            max / min
        } else {
            f64::INFINITY
        }
    }

    /// Back substitution `R x = Q^T b`; call only when well conditioned.
    pub(super) fn solve(&self) -> Vec<f64> {
        let (p, cols) = (self.p, self.p + 1);
        let mut x = vec![0.0; p];
        for i in (0..p).rev() {
            let row = &self.r[i * cols..(i + 1) * cols];
            let s = dot(&row[i + 1..p], &x[i + 1..p]);
            x[i] = (row[p] - s) / row[i];
        }
        x
    }
}

/// Dot product with eight independent accumulators (lets the compiler use
/// SIMD lanes without reassociating a single sum).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0.0; 8];
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7])) + tail
}

/// `y += s x`.
fn axpy(s: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += s * xi;
    }
}
