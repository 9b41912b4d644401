//! Levenberg–Marquardt over Zernike coefficients, on the normal equations
//! of [`super::problem`]. The residuals are screen points in units of their
//! σ; the problem is nearly linear (µm surfaces), so a Gauss–Newton step is
//! accepted almost always and λ only guards the first steps from a flat start.

use nalgebra::{DMatrix, DVector};

use super::problem::{accumulate, Layout, Normal, Observations};
use super::SurfaceError;
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::optics::zernike::ZernikeSurface;

/// Largest condition number of the weighted Jacobian a stage accepts. The
/// normal equations square it; at 1e7 their solution keeps ~2 significant
/// digits in f64 (1e-16 × 1e14), and the coefficient uncertainties are
/// already 1e7 times the best-determined one: the data do not determine
/// the model, and a number is better than a meaningless surface.
pub const MAX_CONDITION_NUMBER: f64 = 1e7;

/// Condition number of the weighted Jacobian, √(λmax/λmin) of JᵀJ.
pub fn condition_number(n: &Normal) -> f64 {
    let eig = n.a.clone().symmetric_eigen().eigenvalues;
    let (lo, hi) = (eig.min(), eig.max());
    if lo > 0.0 {
        (hi / lo).sqrt()
    } else {
        f64::INFINITY
    }
}

/// χ² decrease below which a step with known σ counts as converged.
const CHI2_TOL: f64 = 1e-3;

/// Stopping rules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Iteration cap (normal-equation builds).
    pub max_iter: usize,
    /// Converged when the largest coefficient step is below this, nm.
    pub step_tol_nm: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iter: 30,
            // 1e-4 nm: four decades below the 0.1 nm accuracy asked of the
            // front; a nearly linear problem gets there in 2–4 steps.
            step_tol_nm: 1e-4,
        }
    }
}

/// How a solve ended.
#[derive(Debug, Clone, PartialEq)]
pub struct LmReport {
    /// Normal-equation builds (iterations).
    pub iterations: usize,
    /// χ² (σ-weighted sum of squares) at the start.
    pub chi2_start: f64,
    /// χ² at the end.
    pub chi2: f64,
    /// Residual components at the end.
    pub n_resid: usize,
    /// Whether the step tolerance was reached.
    pub converged: bool,
    /// Why it stopped, in words.
    pub reason: String,
    /// Measured paths the final surfaces could not trace (front, back).
    pub failed: [usize; 2],
}

/// The plate with the free coefficients of `layout` moved by `delta`.
pub fn apply(plate: &Plate, layout: &Layout, delta: &DVector<f64>) -> Result<Plate, SurfaceError> {
    let mut out = plate.clone();
    let mut f = plate.front.coefficients_nm().to_vec();
    for (k, c) in f.iter_mut().enumerate() {
        if let Some(col) = layout.front_col(k) {
            *c += delta[col];
        }
    }
    let mut b = plate.back.coefficients_nm().to_vec();
    for (k, c) in b.iter_mut().enumerate() {
        if let Some(col) = layout.back_col(k) {
            *c += delta[col];
        }
    }
    out.front = ZernikeSurface::new(plate.front.basis().clone(), f)?;
    out.back = ZernikeSurface::new(plate.back.basis().clone(), b)?;
    Ok(out)
}

/// Solves `(A + λ diag A) δ = −b`; `None` when not positive definite.
fn step(n: &Normal, lambda: f64) -> Option<DVector<f64>> {
    let mut a: DMatrix<f64> = n.a.clone();
    for i in 0..a.nrows() {
        a[(i, i)] *= 1.0 + lambda;
    }
    let chol = a.cholesky()?;
    Some(-chol.solve(&n.b))
}

/// Minimises χ² over the free coefficients of `layout`, starting from (and
/// updating) `plate`. Returns the report and the normal equations at the end.
///
/// # Errors
/// [`SurfaceError::TooFewPoints`] when fewer residuals than unknowns remain;
/// [`SurfaceError::IllConditioned`] when the system is singular.
pub fn levenberg_marquardt(
    obs: &Observations,
    station: &Station,
    plate: &mut Plate,
    layout: &Layout,
    stage: &'static str,
    opts: &LmOptions,
) -> Result<(LmReport, Normal), SurfaceError> {
    let p = layout.columns();
    let mut cur = accumulate(obs, station, plate, layout, true);
    if cur.n_resid < p {
        return Err(SurfaceError::TooFewPoints {
            stage,
            have: cur.n_resid,
            need: p,
        });
    }
    let condition_number = condition_number(&cur);
    if condition_number > MAX_CONDITION_NUMBER {
        return Err(SurfaceError::IllConditioned {
            stage,
            condition_number,
        });
    }
    let mut report = LmReport {
        iterations: 1,
        chi2_start: cur.chi2,
        chi2: cur.chi2,
        n_resid: cur.n_resid,
        converged: false,
        reason: String::new(),
        failed: cur.failed,
    };
    let mut lambda = 1e-6;
    while report.iterations < opts.max_iter {
        let Some(delta) = step(&cur, lambda) else {
            if lambda > 1e6 {
                return Err(SurfaceError::IllConditioned {
                    stage,
                    condition_number: f64::INFINITY,
                });
            }
            lambda *= 100.0;
            continue;
        };
        let largest = delta.amax();
        let trial_plate = apply(plate, layout, &delta)?;
        let trial = accumulate(obs, station, &trial_plate, layout, true);
        report.iterations += 1;
        // A step that loses paths is not comparable by χ² alone: reject it.
        let comparable = trial.n_resid >= cur.n_resid;
        if comparable && trial.chi2 <= cur.chi2 {
            let drop = cur.chi2 - trial.chi2;
            *plate = trial_plate;
            cur = trial;
            lambda = (lambda * 0.1).max(1e-12);
            if largest < opts.step_tol_nm {
                report.converged = true;
                report.reason = format!("step below {} nm", opts.step_tol_nm);
                break;
            }
            // With known σ, a χ² drop below 1e-3 means the step moved every
            // coefficient by far less than its own σ (≤ 0.03 σ): converged
            // in the statistical sense; noise-free data use the step rule.
            if obs.sigma_known && drop < CHI2_TOL {
                report.converged = true;
                report.reason = format!("χ² drop {drop:.1e} below {CHI2_TOL}");
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                report.converged = largest < 1e3 * opts.step_tol_nm;
                report.reason = "no step lowers χ² (at its floor)".into();
                break;
            }
        }
    }
    if report.reason.is_empty() {
        report.reason = format!("iteration limit {}", opts.max_iter);
    }
    report.chi2 = cur.chi2;
    report.n_resid = cur.n_resid;
    report.failed = cur.failed;
    Ok((report, cur))
}
