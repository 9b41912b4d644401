//! Levenberg–Marquardt over Zernike coefficients, on the normal equations
//! of [`super::problem`] and the shared loop of [`crate::kernels::lm`]. The
//! residuals are screen points in units of their σ; the problem is nearly
//! linear (µm surfaces), so a Gauss–Newton step is accepted almost always
//! and λ only guards the first steps from a flat start ([`DAMPING`]).

use nalgebra::{DMatrix, DVector};

use super::convergence::StepSize;
use super::problem::{accumulate, Layout, Normal, Observations};
use super::SurfaceError;
use crate::kernels::lm::{self, Damping, LeastSquares, Linearisation, Stop};
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
    /// The last step solved against the σ of the coefficients it moved
    /// (at the end's normal equations); `None` where no step was solved or
    /// the normal equations are singular.
    pub last_step: Option<StepSize>,
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

/// The largest share of the residuals a Levenberg–Marquardt step may lose
/// and still be compared by χ² per residual (see `comparable`): 1e-3, a
/// rim's worth of pixels, not a region.
pub const MAX_LOST_FRACTION: f64 = 1e-3;

/// The surface solvers' damping schedule for the shared loop
/// ([`crate::kernels::lm`], whose policy it parameterises).
///
/// The solve starts from a flat plate (or the previous stage's surfaces) on
/// a nearly linear problem — µm surfaces deflect rays linearly in their
/// coefficients to ~1e-3 — so the Gauss–Newton step is right almost always:
/// λ starts at 1e-6, Gauss–Newton to six digits. An evaluation traces every
/// measured path, so when a step is rejected (it lost paths, or χ² rose)
/// damping must become effective within few of them: ×10, reaching 0.1 in
/// five; ÷10 after an accepted step returns to Gauss–Newton as fast. At λ =
/// 1e8 a step is ~1e-8 of the Gauss–Newton one — for steps of ≲ 1 µm below
/// 1e-5 nm, a tenth of the step tolerance ([`LmOptions::step_tol_nm`]):
/// no step that matters lowers χ², the floor is reached. Floor 1e-12:
/// Gauss–Newton to rounding.
pub const DAMPING: Damping = Damping {
    start: 1e-6,
    up: 10.0,
    down: 10.0,
    floor: 1e-12,
    cap: 1e8,
    trust_prediction_below: None,
    stall: None,
};

/// The normal equations as the shared loop reads them: the problem's
/// residuals are model − data, so the loop's `Jᵀr` is `−b`.
struct Linearised {
    normal: Normal,
    neg_b: DVector<f64>,
}

impl Linearised {
    fn new(normal: Normal) -> Self {
        let neg_b = -&normal.b;
        Linearised { normal, neg_b }
    }
}

impl Linearisation for Linearised {
    fn cost(&self) -> f64 {
        self.normal.chi2
    }

    fn jtj(&self) -> &DMatrix<f64> {
        &self.normal.a
    }

    fn jtr(&self) -> &DVector<f64> {
        &self.neg_b
    }
}

/// One stage's solve as a problem of the shared loop.
struct SurfaceProblem<'a> {
    obs: &'a Observations,
    station: &'a Station,
    layout: &'a Layout,
    opts: &'a LmOptions,
}

impl LeastSquares for SurfaceProblem<'_> {
    type Params = Plate;
    type Normal = Linearised;
    type Error = SurfaceError;

    fn evaluate(&self, plate: &Plate) -> Linearised {
        Linearised::new(accumulate(self.obs, self.station, plate, self.layout, true))
    }

    fn moved(&self, plate: &Plate, step: &DVector<f64>) -> Result<Plate, SurfaceError> {
        apply(plate, self.layout, step)
    }

    /// A step that loses paths is not comparable by χ² alone (fewer terms
    /// sum lower). It is taken only when it loses few of them — at most
    /// [`MAX_LOST_FRACTION`] of the residuals, paths at the rim or the
    /// screen's edge that the better surfaces no longer reach — and lowers
    /// χ² per residual too; otherwise rejected. Rejecting every such step
    /// stalled the back's solve 20× above its χ² when a tilted back's
    /// optimum no longer reaches one rim pixel's screen point.
    fn comparable(&self, current: &Linearised, trial: &Linearised) -> bool {
        let (n_cur, n_trial) = (current.normal.n_resid, trial.normal.n_resid);
        if n_trial >= n_cur {
            return true;
        }
        let lost = (n_cur - n_trial) as f64;
        lost <= MAX_LOST_FRACTION * n_cur as f64
            && trial.normal.chi2 / n_trial as f64 <= current.normal.chi2 / n_cur as f64
    }

    fn small_step(&self, step: &DVector<f64>) -> bool {
        step.amax() < self.opts.step_tol_nm
    }

    /// With known σ, a χ² drop below [`CHI2_TOL`] means the step moved
    /// every coefficient by far less than its own σ (≤ 0.03 σ): converged
    /// in the statistical sense; noise-free data use the step rule.
    fn decrease_tolerance(&self, _at: &Linearised) -> Option<f64> {
        self.obs.sigma_known.then_some(CHI2_TOL)
    }
}

/// Minimises χ² over the free coefficients of `layout` on the shared loop
/// ([`crate::kernels::lm::minimise`], schedule [`DAMPING`]), starting from
/// (and updating) `plate`. Returns the report and the normal equations at
/// the end.
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
    let start = accumulate(obs, station, plate, layout, true);
    if start.n_resid < p {
        return Err(SurfaceError::TooFewPoints {
            stage,
            have: start.n_resid,
            need: p,
        });
    }
    let condition_number = condition_number(&start);
    if condition_number > MAX_CONDITION_NUMBER {
        return Err(SurfaceError::IllConditioned {
            stage,
            condition_number,
        });
    }
    let chi2_start = start.chi2;
    let problem = SurfaceProblem {
        obs,
        station,
        layout,
        opts,
    };
    // The start's build counts as an iteration.
    let max_trials = opts.max_iter.saturating_sub(1);
    let out = lm::minimise(
        &problem,
        plate.clone(),
        Linearised::new(start),
        &DAMPING,
        max_trials,
    )?;
    let Some((converged, reason)) = verdict(out.stop, out.last_step.as_ref(), opts) else {
        return Err(SurfaceError::IllConditioned {
            stage,
            condition_number: f64::INFINITY,
        });
    };
    *plate = out.params;
    let cur = out.normal.normal;
    let last_step = out
        .last_step
        .as_ref()
        .and_then(|s| step_against_sigma(&cur, s, obs.sigma_known));
    let report = LmReport {
        iterations: 1 + out.trials,
        chi2_start,
        chi2: cur.chi2,
        n_resid: cur.n_resid,
        converged,
        reason,
        failed: cur.failed,
        last_step,
    };
    Ok((report, cur))
}

/// The coefficient of `step` that moved most in units of its own σ, and
/// that σ: `√((JᵀJ)⁻¹ᵢᵢ · s)` at the normal equations `n`, `s` the scale the
/// solution's covariance takes (max(1, χ²/dof) with known σ, χ²/dof
/// otherwise; see `solve::finish`). `None` where `n` cannot be inverted.
fn step_against_sigma(n: &Normal, step: &DVector<f64>, sigma_known: bool) -> Option<StepSize> {
    let inv = n.a.clone().cholesky()?.inverse();
    let dof = n.n_resid.saturating_sub(n.a.nrows()).max(1) as f64;
    let reduced = n.chi2 / dof;
    let scale = if sigma_known {
        reduced.max(1.0)
    } else {
        reduced
    };
    (0..step.len().min(inv.nrows()))
        .map(|i| StepSize {
            step_nm: step[i].abs(),
            sigma_nm: (inv[(i, i)] * scale).max(0.0).sqrt(),
        })
        .max_by(|a, b| a.in_sigma().total_cmp(&b.in_sigma()))
}

/// Whether the loop's stop is convergence, and why in words; `None` where
/// the damped system was singular at every damping. At the floor (no step
/// lowers χ²) the point counts as converged when the last step tried was
/// within 1e3 step tolerances: a minimum to rounding, not a stall far off.
fn verdict(
    stop: Stop,
    last_step: Option<&DVector<f64>>,
    opts: &LmOptions,
) -> Option<(bool, String)> {
    Some(match stop {
        Stop::SmallStep => (true, format!("step below {} nm", opts.step_tol_nm)),
        Stop::SmallDecrease { decrease }
        | Stop::PredictedSmall {
            predicted: decrease,
        } => (true, format!("χ² drop {decrease:.1e} below {CHI2_TOL}")),
        Stop::Floor => {
            let largest = last_step.map_or(0.0, |s| s.amax());
            (
                largest < 1e3 * opts.step_tol_nm,
                "no step lowers χ² (at its floor)".into(),
            )
        }
        Stop::Singular => return None,
        // The surfaces' schedule has no stall test ([`DAMPING`]).
        Stop::Stalled { decrease } => (
            true,
            format!("χ² drop {decrease:.1e} over the stall window"),
        ),
        Stop::TrialLimit => (false, format!("iteration limit {}", opts.max_iter)),
    })
}
