//! Weighted least-squares fits of Zernike coefficients to heights or slopes,
//! by incremental blocked Householder QR (the design matrix is never stored).

use super::qr::{Factor, IncrementalQr};
use super::{ZernikeBasis, ZernikeError, MAX_CONDITION_NUMBER, MM_PER_NM, NM_PER_MM};

/// Result of a Zernike least-squares fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ZernikeFit {
    /// Fitted coefficients, nm; index k holds Noll j = k + 1 (same basis as
    /// the fit). For slope fits index 0 (piston) is always 0.
    pub coefficients_nm: Vec<f64>,
    /// 2-norm condition number of the weighted design matrix (largest over
    /// smallest singular value), at most [`MAX_CONDITION_NUMBER`].
    pub condition_number: f64,
    /// Weighted RMS of the fit residual, `sqrt(sum w r^2 / sum w)`, in the
    /// units of the data: mm for heights, mm/mm for slopes (both components
    /// pooled).
    pub residual_rms: f64,
    /// Points that entered the fit (those with a positive weight).
    pub n_points: usize,
}

/// Fit `heights_mm` (mm) at world points `(xs_mm, ys_mm)` (mm) with all
/// `basis.n_terms()` terms, minimising `sum_i w_i (W(x_i, y_i) - h_i)^2`.
///
/// `weights` (default all 1) must be finite and >= 0; points of weight 0 are
/// skipped. Memory is O(n_terms^2) whatever the number of points.
///
/// # Errors
/// [`ZernikeError::LengthMismatch`], [`ZernikeError::NonFinite`],
/// [`ZernikeError::InvalidWeight`] for bad input;
/// [`ZernikeError::TooFewPoints`] with fewer usable points than terms;
/// [`ZernikeError::IllConditioned`] when the condition number exceeds
/// [`MAX_CONDITION_NUMBER`] (e.g. all points on a line).
pub fn fit_heights(
    basis: &ZernikeBasis,
    xs_mm: &[f64],
    ys_mm: &[f64],
    heights_mm: &[f64],
    weights: Option<&[f64]>,
) -> Result<ZernikeFit, ZernikeError> {
    let data = [
        ("xs_mm", xs_mm),
        ("ys_mm", ys_mm),
        ("heights_mm", heights_mm),
    ];
    let (points, w_max) = validate(&data, weights)?;
    let p = basis.n_terms();
    check_count(points, points, p)?;
    let mut qr = IncrementalQr::new(p);
    let mut row = vec![0.0; p + 1];
    let mut weight_sum = 0.0;
    for i in 0..xs_mm.len() {
        let w = weights.map_or(1.0, |w| w[i] / w_max);
        if w == 0.0 {
            continue;
        }
        basis.fill_values(xs_mm[i], ys_mm[i], &mut row[..p]);
        row[p] = heights_mm[i] * NM_PER_MM;
        qr.push_row(&row, w.sqrt());
        weight_sum += w;
    }
    let (coefficients_nm, condition_number, residual) = solve(qr.finish())?;
    Ok(ZernikeFit {
        coefficients_nm,
        condition_number,
        residual_rms: residual * MM_PER_NM / weight_sum.sqrt(),
        n_points: points,
    })
}

/// Fit surface slopes `dzdx`, `dzdy` (dimensionless, mm/mm) at world points
/// `(xs_mm, ys_mm)` (mm), minimising
/// `sum_i w_i ((dW/dx - dzdx_i)^2 + (dW/dy - dzdy_i)^2)`.
///
/// Piston (Noll j = 1) has zero gradient and is not observable from slopes:
/// it is excluded from the unknowns and reported as 0. All other terms of
/// `basis` are fitted. Each point gives two equations.
///
/// # Errors
/// As [`fit_heights`]; [`ZernikeError::TooFewPoints`] when `2 x points` is
/// below `n_terms - 1`.
pub fn fit_slopes(
    basis: &ZernikeBasis,
    xs_mm: &[f64],
    ys_mm: &[f64],
    dzdx: &[f64],
    dzdy: &[f64],
    weights: Option<&[f64]>,
) -> Result<ZernikeFit, ZernikeError> {
    let data = [
        ("xs_mm", xs_mm),
        ("ys_mm", ys_mm),
        ("dzdx", dzdx),
        ("dzdy", dzdy),
    ];
    let (points, w_max) = validate(&data, weights)?;
    let n = basis.n_terms();
    let p = n - 1;
    check_count(points, 2 * points, p)?;
    let mut qr = IncrementalQr::new(p);
    let (mut v, mut gx, mut gy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut row = vec![0.0; p + 1];
    let mut weight_sum = 0.0;
    for i in 0..xs_mm.len() {
        let w = weights.map_or(1.0, |w| w[i] / w_max);
        if w == 0.0 {
            continue;
        }
        basis.fill_with_gradients(xs_mm[i], ys_mm[i], &mut v, &mut gx, &mut gy);
        let scale = w.sqrt();
        for (g, slope) in [(&gx, dzdx[i]), (&gy, dzdy[i])] {
            row[..p].copy_from_slice(&g[1..]);
            row[p] = slope * NM_PER_MM; // nm per mm, matching dZ/dx per mm x nm
            qr.push_row(&row, scale);
        }
        weight_sum += 2.0 * w;
    }
    let (fitted, condition_number, residual) = solve(qr.finish())?;
    let mut coefficients_nm = Vec::with_capacity(n);
    coefficients_nm.push(0.0);
    coefficients_nm.extend_from_slice(&fitted);
    Ok(ZernikeFit {
        coefficients_nm,
        condition_number,
        residual_rms: residual * MM_PER_NM / weight_sum.sqrt(),
        n_points: points,
    })
}

/// Check lengths, finiteness and weights. Returns the number of points with a
/// positive weight and the largest weight (1 without weights). Weights are
/// divided by it, so they are at most 1 and neither squares of huge weights
/// overflow nor 1 / (tiny weight) does; the solution is unchanged.
fn validate(
    data: &[(&'static str, &[f64])],
    weights: Option<&[f64]>,
) -> Result<(usize, f64), ZernikeError> {
    let n = data[0].1.len();
    let all = data.iter().copied().chain(weights.map(|w| ("weights", w)));
    for (what, values) in all {
        if values.len() != n {
            return Err(ZernikeError::LengthMismatch {
                what,
                expected: n,
                actual: values.len(),
            });
        }
    }
    for (what, values) in data {
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(ZernikeError::NonFinite { what, index });
        }
    }
    let Some(w) = weights else {
        return Ok((n, 1.0));
    };
    if let Some(index) = w.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(ZernikeError::InvalidWeight {
            index,
            weight: w[index],
        });
    }
    let w_max = w.iter().fold(0.0_f64, |a, &b| a.max(b));
    let used = w.iter().filter(|&&v| v > 0.0).count();
    Ok((used, if w_max > 0.0 { w_max } else { 1.0 }))
}

fn check_count(points: usize, equations: usize, unknowns: usize) -> Result<(), ZernikeError> {
    if equations < unknowns || points == 0 {
        Err(ZernikeError::TooFewPoints {
            points,
            equations,
            unknowns,
        })
    } else {
        Ok(())
    }
}

/// Condition check and back substitution: (solution, condition, ||residual||).
fn solve(factor: Factor) -> Result<(Vec<f64>, f64, f64), ZernikeError> {
    if let Some(index) = factor.r.iter().position(|v| !v.is_finite()) {
        return Err(ZernikeError::NonFinite {
            what: "triangular factor (overflow)",
            index,
        });
    }
    // Never NaN: condition_number() returns +inf for every degenerate case.
    let condition_number = factor.condition_number();
    if condition_number > MAX_CONDITION_NUMBER {
        return Err(ZernikeError::IllConditioned { condition_number });
    }
    let x = factor.solve();
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(ZernikeError::NonFinite {
            what: "fitted coefficients (overflow)",
            index,
        });
    }
    Ok((x, condition_number, factor.residual_norm()))
}
