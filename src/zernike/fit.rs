//! Least-squares Zernike fits of heights and of slopes, by a blocked
//! Householder QR that never holds the full design matrix: each block of
//! rows is stacked under the running triangular factor and re-factored.

use nalgebra::{DMatrix, DVector};

use super::{ZernikeBasis, ZernikeError, NM_PER_MM};

/// Rows per QR block: large enough to amortise the re-factoring of R, small
/// enough (4096 × 231 × 8 B = 7.6 MB) to stay in cache-friendly memory.
const BLOCK_ROWS: usize = 4096;
/// Condition numbers above this leave fewer than ~4 significant digits in
/// the coefficients (f64 has 16): the fit is refused.
const MAX_CONDITION: f64 = 1e12;

/// The result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ZernikeFit {
    /// Coefficients, nm (index k = Noll j − 1).
    pub coefficients_nm: Vec<f64>,
    /// Ratio of the largest to the smallest singular value of the (weighted) design.
    pub condition_number: f64,
    /// RMS of the weighted residuals, in the data's unit (mm for heights,
    /// dimensionless for slopes).
    pub residual_rms: f64,
    /// Data rows used (points for heights, 2 × points for slopes).
    pub rows: usize,
}

/// Running `R` and `Qᵀ b` of a blocked QR.
struct Accumulator {
    unknowns: usize,
    r: DMatrix<f64>,
    qtb: DVector<f64>,
    rss: f64,
    rows: usize,
    block: DMatrix<f64>,
    rhs: DVector<f64>,
    fill: usize,
}

impl Accumulator {
    fn new(unknowns: usize) -> Self {
        Accumulator {
            unknowns,
            r: DMatrix::zeros(0, unknowns),
            qtb: DVector::zeros(0),
            rss: 0.0,
            rows: 0,
            block: DMatrix::zeros(BLOCK_ROWS, unknowns),
            rhs: DVector::zeros(BLOCK_ROWS),
            fill: 0,
        }
    }

    fn push(&mut self, row: &[f64], value: f64) {
        for (c, &v) in row.iter().enumerate() {
            self.block[(self.fill, c)] = v;
        }
        self.rhs[self.fill] = value;
        self.fill += 1;
        self.rows += 1;
        if self.fill == BLOCK_ROWS {
            self.flush();
        }
    }

    fn flush(&mut self) {
        if self.fill == 0 {
            return;
        }
        let (u, k) = (self.unknowns, self.r.nrows());
        let mut m = DMatrix::zeros(k + self.fill, u);
        m.rows_mut(0, k).copy_from(&self.r);
        m.rows_mut(k, self.fill)
            .copy_from(&self.block.rows(0, self.fill));
        let mut b = DVector::zeros(k + self.fill);
        b.rows_mut(0, k).copy_from(&self.qtb);
        b.rows_mut(k, self.fill)
            .copy_from(&self.rhs.rows(0, self.fill));
        let qr = m.qr();
        qr.q_tr_mul(&mut b);
        let keep = u.min(k + self.fill);
        self.rss += b.rows(keep, b.len() - keep).norm_squared();
        self.r = qr.r().rows(0, keep).into_owned();
        self.qtb = b.rows(0, keep).into_owned();
        self.fill = 0;
    }

    fn solve(mut self) -> Result<(DVector<f64>, f64, f64, usize), ZernikeError> {
        self.flush();
        if self.rows < self.unknowns {
            return Err(ZernikeError::TooFewPoints {
                rows: self.rows,
                unknowns: self.unknowns,
            });
        }
        let sv = self.r.clone().singular_values();
        let (hi, lo) = (sv.max(), sv.min());
        let condition_number = if lo > 0.0 { hi / lo } else { f64::INFINITY };
        if condition_number.is_nan() || condition_number > MAX_CONDITION {
            return Err(ZernikeError::IllConditioned { condition_number });
        }
        let x = self
            .r
            .solve_upper_triangular(&self.qtb)
            .ok_or(ZernikeError::IllConditioned { condition_number })?;
        let rms = (self.rss / self.rows as f64).sqrt();
        Ok((x, condition_number, rms, self.rows))
    }
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), ZernikeError> {
    if expected == found {
        Ok(())
    } else {
        Err(ZernikeError::LengthMismatch {
            what,
            expected,
            found,
        })
    }
}

/// Fits `heights_mm` at `(xs_mm, ys_mm)` with all terms of `basis`;
/// `weights` (optional) multiply each squared residual.
///
/// # Errors
/// Length mismatches, too few points, or a condition number above 1e12.
pub fn fit_heights(
    basis: &ZernikeBasis,
    xs_mm: &[f64],
    ys_mm: &[f64],
    heights_mm: &[f64],
    weights: Option<&[f64]>,
) -> Result<ZernikeFit, ZernikeError> {
    let n = xs_mm.len();
    check_len("ys_mm", n, ys_mm.len())?;
    check_len("heights_mm", n, heights_mm.len())?;
    if let Some(w) = weights {
        check_len("weights", n, w.len())?;
    }
    let u = basis.n_terms();
    let mut acc = Accumulator::new(u);
    let mut row = vec![0.0; u];
    for p in 0..n {
        let sw = weights.map_or(1.0, |w| w[p].max(0.0).sqrt());
        basis.eval_values_into(xs_mm[p], ys_mm[p], &mut row);
        row.iter_mut().for_each(|v| *v *= sw);
        acc.push(&row, sw * heights_mm[p] * NM_PER_MM);
    }
    let (x, condition_number, rms, rows) = acc.solve()?;
    Ok(ZernikeFit {
        coefficients_nm: x.iter().copied().collect(),
        condition_number,
        residual_rms: rms / NM_PER_MM,
        rows,
    })
}

/// Fits slopes `(∂W/∂x, ∂W/∂y)` (dimensionless) at `(xs_mm, ys_mm)` with the
/// gradients of terms j = 2 … n_terms. Piston (j = 1) has no slope and is not
/// observable: it is not an unknown and is returned as 0.
///
/// # Errors
/// Length mismatches, too few points, or a condition number above 1e12.
pub fn fit_slopes(
    basis: &ZernikeBasis,
    xs_mm: &[f64],
    ys_mm: &[f64],
    dzdx: &[f64],
    dzdy: &[f64],
    weights: Option<&[f64]>,
) -> Result<ZernikeFit, ZernikeError> {
    let n = xs_mm.len();
    check_len("ys_mm", n, ys_mm.len())?;
    check_len("dzdx", n, dzdx.len())?;
    check_len("dzdy", n, dzdy.len())?;
    if let Some(w) = weights {
        check_len("weights", n, w.len())?;
    }
    let u = basis.n_terms();
    if u < 2 {
        return Err(ZernikeError::TooFewPoints {
            rows: 2 * n,
            unknowns: 0,
        });
    }
    let mut acc = Accumulator::new(u - 1);
    let (mut v, mut gx, mut gy) = (vec![0.0; u], vec![0.0; u], vec![0.0; u]);
    for p in 0..n {
        let sw = weights.map_or(1.0, |w| w[p].max(0.0).sqrt());
        basis.eval_into(xs_mm[p], ys_mm[p], &mut v, &mut gx, &mut gy);
        // Basis gradients are per mm of a unit-coefficient term; a coefficient
        // in nm adds 1e-6 × that to the dimensionless slope.
        gx[1..].iter_mut().for_each(|g| *g *= sw / NM_PER_MM);
        gy[1..].iter_mut().for_each(|g| *g *= sw / NM_PER_MM);
        acc.push(&gx[1..], sw * dzdx[p]);
        acc.push(&gy[1..], sw * dzdy[p]);
    }
    let (x, condition_number, rms, rows) = acc.solve()?;
    let mut coefficients_nm = vec![0.0];
    coefficients_nm.extend(x.iter());
    Ok(ZernikeFit {
        coefficients_nm,
        condition_number,
        residual_rms: rms,
        rows,
    })
}
