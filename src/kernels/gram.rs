//! `A Aᵀ` of a column-major block whose columns are the residuals' rows of
//! a Jacobian (`A = Jᵀ`), without the transposed copy `gemm(A, Aᵀ)` would
//! take: the transpose is a view of the same storage with its strides
//! swapped, and nalgebra hands both to matrixmultiply's blocked kernel with
//! their strides, which packs them into its panels directly.
//!
//! The solvers' normal-equation sums call this once per chunk of pixels; the
//! copy it avoids was a 4.9 MB strided transpose per 512-pixel chunk of a
//! 300-column problem, as much memory traffic as the product's packing.
//! The result is the same bits as `gemm(1, A, Aᵀ.clone(), 0)`: the packed
//! panels hold the same numbers in the same order.

use nalgebra::{DMatrix, DMatrixView};

/// `A Aᵀ` for `A` the first `cols` columns of the column-major `rows × …`
/// storage `data` (`data.len() ≥ rows · cols`).
///
/// # Panics
/// When `data` is shorter than `rows · cols`.
pub fn gram_of_columns(data: &[f64], rows: usize, cols: usize) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(rows, rows);
    if rows == 0 || cols == 0 {
        return out;
    }
    let data = &data[..rows * cols];
    let a = DMatrixView::from_slice(data, rows, cols);
    // Aᵀ: element (i, t) of the `cols × rows` view is A's (t, i), at
    // `t + i · rows`: row stride `rows`, column stride 1.
    let at = DMatrixView::from_slice_with_strides(data, cols, rows, rows, 1);
    out.gemm(1.0, &a, &at, 0.0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gram_is_the_copying_products_bits() {
        // Sizes on both sides of nalgebra's small-matrix threshold (5) and
        // of matrixmultiply's panel widths.
        for (rows, cols) in [(3, 4), (7, 9), (37, 130), (64, 517)] {
            let m = DMatrix::<f64>::from_fn(rows, cols + 3, |i, j| {
                ((i * 31 + j * 17) as f64 * 0.123).sin() * 10f64.powi((i % 5) as i32 - 2)
            });
            let jt = m.columns(0, cols);
            let mut want = DMatrix::zeros(rows, rows);
            want.gemm(1.0, &jt, &jt.transpose(), 0.0);
            let got = gram_of_columns(m.as_slice(), rows, cols);
            for (g, w) in got.iter().zip(want.iter()) {
                assert_eq!(g.to_bits(), w.to_bits(), "{rows}×{cols}");
            }
        }
    }
}
