//! The one small Cholesky factorisation, on the stack: `A = L Lᵀ` of a
//! symmetric positive definite matrix of at most `N` rows, `N` a compile-time
//! capacity. The spectral fits factor a 5×5 or 8×8 JᵀJ several times per
//! pixel (capacity 11, three reflections), where a heap-allocated
//! factorisation cost ~15 % of the solve; the surface solvers whiten each
//! pixel's residuals with the Cholesky factor of its 2×2 to 4×4 covariance
//! (capacity 4). Large dense systems (the surface solvers' Zernike normal
//! equations) go to nalgebra's Cholesky instead.

use nalgebra::{DMatrix, DVector};

/// The Cholesky factor `L` (`A = L Lᵀ`) of an `n × n` symmetric positive
/// definite matrix, `n ≤ N`, held on the stack.
#[derive(Debug, Clone)]
pub struct SmallCholesky<const N: usize> {
    n: usize,
    l: [[f64; N]; N],
    /// `1 / L_jj`: the solves multiply (a division's latency is ~15
    /// cycles, and a pixel's ~10 solves have 16 each on their critical path).
    inv_diag: [f64; N],
}

impl<const N: usize> SmallCholesky<N> {
    /// Factors the `n × n` matrix whose entry `(i, j)`, `i ≥ j`, is
    /// `a(i, j)` (only the lower triangle is read); `None` unless `n ≤ N`
    /// and it is positive definite (every pivot positive and finite).
    #[inline]
    pub fn from_fn(n: usize, a: impl Fn(usize, usize) -> f64) -> Option<Self> {
        if n > N {
            return None;
        }
        let mut l = [[0.0; N]; N];
        let mut inv_diag = [0.0; N];
        for j in 0..n {
            let lj = l[j];
            let d = a(j, j) - lj[..j].iter().map(|x| x * x).sum::<f64>();
            if !(d > 0.0 && d.is_finite()) {
                return None;
            }
            let dj = d.sqrt();
            let rj = 1.0 / dj;
            l[j][j] = dj;
            inv_diag[j] = rj;
            for (i, li) in l.iter_mut().enumerate().take(n).skip(j + 1) {
                let dot: f64 = li[..j].iter().zip(&lj[..j]).map(|(x, y)| x * y).sum();
                li[j] = (a(i, j) - dot) * rj;
            }
        }
        Some(SmallCholesky { n, l, inv_diag })
    }

    /// Factors `a` (its lower triangle is read); `None` unless it is
    /// square, at most `N × N` and positive definite.
    #[inline]
    pub fn new(a: &DMatrix<f64>) -> Option<Self> {
        if a.ncols() != a.nrows() {
            return None;
        }
        Self::from_fn(a.nrows(), |i, j| a[(i, j)])
    }

    /// The factor of the diagonal matrix `diag(d)`, `L = diag(√d)`, without
    /// checks: a zero or negative entry gives infinite or NaN solves (the
    /// caller's fallback where a full matrix was not positive definite).
    ///
    /// # Panics
    /// When `d` has more than `N` entries.
    pub fn diagonal(d: &[f64]) -> Self {
        assert!(d.len() <= N, "{} entries for capacity {N}", d.len());
        let mut l = [[0.0; N]; N];
        let mut inv_diag = [0.0; N];
        for (i, &v) in d.iter().enumerate() {
            l[i][i] = v.sqrt();
            inv_diag[i] = 1.0 / l[i][i];
        }
        SmallCholesky {
            n: d.len(),
            l,
            inv_diag,
        }
    }

    /// Rows (and columns) of the factored matrix.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// `x ← L⁻¹ x` (forward substitution) on the first [`Self::dim`]
    /// entries: whitens a vector whose covariance is the factored matrix.
    #[inline]
    pub fn forward_in_place(&self, x: &mut [f64]) {
        let (l, r) = (&self.l, &self.inv_diag);
        for i in 0..self.n {
            let mut s = x[i];
            for k in 0..i {
                s -= l[i][k] * x[k];
            }
            x[i] = s * r[i];
        }
    }

    /// `x ← A⁻¹ x` on the first [`Self::dim`] entries.
    #[inline]
    pub fn solve_in_place(&self, x: &mut [f64]) {
        self.forward_in_place(x);
        let (l, r) = (&self.l, &self.inv_diag);
        for i in (0..self.n).rev() {
            let mut s = x[i];
            for k in i + 1..self.n {
                s -= l[k][i] * x[k];
            }
            x[i] = s * r[i];
        }
    }

    /// `A⁻¹ b`.
    #[inline]
    pub fn solve(&self, b: &DVector<f64>) -> DVector<f64> {
        let mut x = [0.0; N];
        x[..self.n].copy_from_slice(b.as_slice());
        self.solve_in_place(&mut x);
        DVector::from_column_slice(&x[..self.n])
    }

    /// `A⁻¹ = L⁻ᵀ L⁻¹`: `W = L⁻¹` by forward substitution, then `WᵀW`
    /// (symmetric by construction; ~n³/3 multiply–adds against the ~n³ of
    /// n solves).
    pub fn inverse(&self) -> DMatrix<f64> {
        let (n, l, r) = (self.n, &self.l, &self.inv_diag);
        // w[i][j], j ≤ i: column j of L⁻¹.
        let mut w = [[0.0; N]; N];
        for j in 0..n {
            w[j][j] = r[j];
            for i in j + 1..n {
                let mut s = 0.0;
                for k in j..i {
                    s += l[i][k] * w[k][j];
                }
                w[i][j] = -s * r[i];
            }
        }
        let mut inv = DMatrix::zeros(n, n);
        for i in 0..n {
            for j in i..n {
                let s: f64 = w[j..n].iter().map(|row| row[i] * row[j]).sum();
                inv[(i, j)] = s;
                inv[(j, i)] = s;
            }
        }
        inv
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A well-conditioned SPD matrix of size `n`: BᵀB + I.
    fn spd(n: usize) -> DMatrix<f64> {
        let b = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 11) as f64 * 0.1 - 0.5);
        b.transpose() * &b + DMatrix::identity(n, n)
    }

    #[test]
    fn small_cholesky_inverts_and_solves_like_nalgebra() {
        // The spectral model's largest size (11).
        let n = 11;
        let a = spd(n);
        let rhs = DVector::from_fn(n, |i, _| i as f64 - 3.0);
        let ours = SmallCholesky::<11>::new(&a).expect("positive definite");
        let theirs = a.clone().cholesky().expect("positive definite");
        // Both are backward stable: with cond(A) ≤ ~1e2 the two differ by
        // rounding, far below 1e-12.
        assert!((ours.solve(&rhs) - theirs.solve(&rhs)).amax() < 1e-12);
        assert!((ours.inverse() - theirs.inverse()).amax() < 1e-12);
        // Not positive definite, or not finite: refused.
        let mut bad = a.clone();
        bad[(4, 4)] = -1.0;
        assert!(SmallCholesky::<11>::new(&bad).is_none());
        bad[(4, 4)] = f64::NAN;
        assert!(SmallCholesky::<11>::new(&bad).is_none());
        // Larger than the capacity: refused.
        assert!(SmallCholesky::<4>::new(&a).is_none());
    }

    #[test]
    fn forward_substitution_whitens_like_nalgebra() {
        // The surface solvers' use: L⁻¹ r of a 4×4 covariance, against
        // nalgebra's factor and triangular solve; same rounding argument.
        let c = spd(4);
        let r = DVector::from_fn(4, |i, _| 1.5 - i as f64);
        let ours = SmallCholesky::<4>::from_fn(4, |i, j| c[(i, j)]).expect("positive definite");
        let mut x = [0.0; 4];
        x.copy_from_slice(r.as_slice());
        ours.forward_in_place(&mut x);
        let l = c.clone().cholesky().expect("positive definite").l();
        let theirs = l.solve_lower_triangular(&r).expect("invertible");
        assert!((DVector::from_column_slice(&x) - theirs).amax() < 1e-12);
        // The diagonal factor: division by the standard deviations.
        let d = SmallCholesky::<4>::diagonal(&[4.0, 9.0]);
        let mut y = [2.0, 3.0, 7.0, 7.0];
        d.forward_in_place(&mut y);
        assert_eq!(y, [1.0, 1.0, 7.0, 7.0]);
    }
}
