//! One weighted least-squares adjustment over a chosen set of the
//! calibration's unknowns ([`super::params::Param`]) and residual blocks
//! ([`Blocks`]), on the shared Levenberg–Marquardt loop
//! ([`crate::kernels::lm`]): the resection, the screen from the flat and the
//! joint adjustment are all this function with different sets.
//!
//! # One estimator: the priors are in the cost
//! Every parameter with a prior range (what the nominal station may be off
//! by) carries it as a pseudo-observation `(x − nominal) / prior` in the
//! cost: the adjustment is a maximum a posteriori one, and its covariance
//! `(N + P)⁻¹` (N the data's normal matrix, P the priors' precisions)
//! includes them. The rule that holds parameters judges with the same
//! priors: a parameter the data do not determine better than its prior
//! range (a degeneracy, or data too weak) is held at its nominal value,
//! worst first, one at a time. So the cost and the hold rule agree: a
//! combination the data leave weak (a camera and screen sliding along the
//! line of sight while the focal length follows, with targets at nearly
//! one distance) is bounded by the priors in both, and named in the
//! report ([`super::weak`]) rather than wandered along.
//!
//! The result's covariance is the inverse normal matrix over the estimated
//! parameters, priors included, plus what the held ones' prior σ does to
//! them through their correlation (the "consider" covariance), so that it
//! covers the error of every parameter, held or estimated. The condition
//! numbers of the correlation-scaled data matrix are kept for the report.
//!
//! The Jacobian is by central differences: the residuals go through the
//! distortion's Newton inverse and the cover glass's refraction, whose
//! analytic derivatives would be as long as the rest of the module, and the
//! problem is small (tens of parameters).

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::error::CalibrationError;
use super::hold::submatrix;
pub use super::hold::{select, Held, Selection};
use super::input::CalibrationInput;
use super::params::{difference, Param, State};
use super::residuals::{item, item_count, Blocks, Whitening};
use super::valley::curvature;
use super::weak::{failure_detail, weak_directions, WeakDirection};
use crate::kernels::lm::{minimise, Damping, LeastSquares, Linearisation, Stall};

/// The schedule: the calibration starts within millimetres and tenths of a
/// degree of its optimum on a nearly linear problem (the targets' and the
/// flat's residuals are smooth in every parameter), so Gauss–Newton is
/// right from the first step and damping only guards against a poor
/// nominal station; each evaluation is cheap, so every step is evaluated.
/// Where a session leaves a weak direction the valley along it is curved
/// (a camera sliding along its line of sight while the focal length
/// follows), and LM can crawl: the stall test ends the crawl once 40
/// trials have lowered χ² by less than 0.05 in all, a fall that moves the
/// point by under a quarter of its σ along any direction the data see
/// (Δχ² = 1 at 1 σ), and lets it go on for as long as it buys more.
const DAMPING: Damping = Damping {
    start: 1e-4,
    up: 10.0,
    down: 10.0,
    floor: 1e-12,
    cap: 1e10,
    trust_prediction_below: None,
    stall: Some(Stall {
        window: 40,
        decrease: 0.05,
    }),
};

/// Trial steps allowed per adjustment: a guard against a loop that keeps
/// making progress for ever (a bug), not the convergence rule (the stall
/// test is); at about 20 ms a trial on a full session, 20 s.
const MAX_TRIALS: usize = 1000;

/// A cost decrease below this (χ² units) is no progress: a thousandth of
/// the χ² a single residual contributes.
const COST_TOLERANCE: f64 = 1e-3;

/// The normal equations of the whitened residuals at one point.
#[derive(Debug, Clone)]
pub struct Normal {
    cost: f64,
    jtj: DMatrix<f64>,
    jtr: DVector<f64>,
    /// The priors' part of the cost.
    prior_cost: f64,
    /// Number of residuals (data alone).
    pub residuals: usize,
}

impl Linearisation for Normal {
    fn cost(&self) -> f64 {
        self.cost
    }
    fn jtj(&self) -> &DMatrix<f64> {
        &self.jtj
    }
    fn jtr(&self) -> &DVector<f64> {
        &self.jtr
    }
}

pub(super) struct Problem<'a> {
    pub(super) input: &'a CalibrationInput,
    pub(super) params: &'a [Param],
    pub(super) blocks: Blocks,
    pub(super) whitening: &'a Whitening,
    /// Where the priors are centred; `None`: the data alone (what the hold
    /// rule reads, adding the priors itself).
    pub(super) nominal: Option<&'a State>,
}

impl LeastSquares for Problem<'_> {
    type Params = State;
    type Normal = Normal;
    type Error = std::convert::Infallible;

    /// Accumulates `JᵀJ`, `Jᵀr` and the cost reading by reading (each one's
    /// rows from the base state and the states shifted by ± each
    /// parameter's step), so that a flat map of every camera pixel needs no
    /// Jacobian in memory.
    fn evaluate(&self, p: &State) -> Normal {
        let n = self.params.len();
        let shifted: Vec<(State, State, f64)> = self
            .params
            .iter()
            .map(|q| {
                (
                    p.perturbed(*q, q.step()),
                    p.perturbed(*q, -q.step()),
                    q.step(),
                )
            })
            .collect();
        let (input, blocks, w) = (self.input, self.blocks, self.whitening);
        let zero = || (DMatrix::zeros(n, n), DVector::zeros(n), 0.0, 0usize);
        let (jtj, jtr, cost, residuals) = (0..item_count(input, blocks))
            .into_par_iter()
            .with_min_len(16)
            .fold(zero, |(mut a, mut g, mut c, mut m), k| {
                let (r0, len) = item(input, p, blocks, w, k);
                let mut rows = DMatrix::zeros(len, n);
                for (col, (plus, minus, h)) in shifted.iter().enumerate() {
                    let (rp, _) = item(input, plus, blocks, w, k);
                    let (rm, _) = item(input, minus, blocks, w, k);
                    for row in 0..len {
                        rows[(row, col)] = (rp[row] - rm[row]) / (2.0 * h);
                    }
                }
                let r = DVector::from_column_slice(&r0[..len]);
                a += rows.transpose() * &rows;
                g -= rows.transpose() * &r;
                c += r.norm_squared();
                m += len;
                (a, g, c, m)
            })
            .reduce(zero, |x, y| (x.0 + y.0, x.1 + y.1, x.2 + y.2, x.3 + y.3));
        let (mut jtj, mut jtr, mut prior_cost) = (jtj, jtr, 0.0);
        if let Some(nominal) = self.nominal {
            // `r = (x − nominal) / prior`, whose derivative along the
            // parameter's own coordinate is `1 / prior`.
            let off = difference(nominal, p, self.params);
            for (k, q) in self.params.iter().enumerate() {
                if let Some(sd) = q.prior_std() {
                    let r = off[k] / sd;
                    jtj[(k, k)] += 1.0 / (sd * sd);
                    jtr[k] -= r / sd;
                    prior_cost += r * r;
                }
            }
        }
        let cost = cost + prior_cost;
        Normal {
            cost: if cost.is_finite() {
                cost
            } else {
                f64::INFINITY
            },
            jtj,
            jtr,
            prior_cost,
            residuals,
        }
    }

    fn moved(&self, p: &State, step: &DVector<f64>) -> Result<State, Self::Error> {
        Ok(self
            .params
            .iter()
            .zip(step.iter())
            .fold(p.clone(), |s, (param, d)| s.perturbed(*param, *d)))
    }

    fn small_step(&self, step: &DVector<f64>) -> bool {
        // A thousandth of each parameter's difference step: far below any σ.
        self.params
            .iter()
            .zip(step.iter())
            .all(|(p, d)| d.abs() <= 1e-3 * p.step())
    }

    fn decrease_tolerance(&self, _at: &Normal) -> Option<f64> {
        Some(COST_TOLERANCE)
    }
}

/// The data's normal matrix `N = JᵀJ` of `blocks` over `params` at
/// `state` (whitened as the adjustment whitens them; no priors): what the
/// readings could tell of the parameters, for a check before solving.
///
/// # Errors
/// [`CalibrationError::BadCovariance`] where a reading's noise is not
/// positive definite.
pub fn information(
    input: &CalibrationInput,
    state: &State,
    params: &[Param],
    blocks: Blocks,
) -> Result<DMatrix<f64>, CalibrationError> {
    let whitening = Whitening::at(input, state)?;
    let problem = Problem {
        input,
        params,
        blocks,
        whitening: &whitening,
        nominal: None,
    };
    Ok(problem.evaluate(state).jtj)
}

/// What one adjustment ends with.
#[derive(Debug, Clone)]
pub struct Adjusted {
    /// The adjusted state.
    pub state: State,
    /// What was estimated and held.
    pub selection: Selection,
    /// Every candidate parameter, estimated first, then held.
    pub params: Vec<Param>,
    /// Covariance over `params` (consider covariance for the held ones).
    pub covariance: DMatrix<f64>,
    /// χ² of the data at the end (the priors' part of the cost apart).
    pub chi2: f64,
    /// The priors' part of the cost at the end: `Σ ((x − nominal)/prior)²`.
    pub prior_chi2: f64,
    /// Residuals minus what the estimated parameters take of them: their
    /// number less `tr(N (N + P)⁻¹)`, the data's share of each parameter
    /// (1 where the data determine it, 0 where its prior does), rounded.
    pub dof: usize,
    /// Trial steps evaluated.
    pub trials: usize,
    /// Why the adjustment stopped.
    pub stop: crate::kernels::lm::Stop,
    /// Combinations of the estimated parameters that the data leave weak.
    pub weak: Vec<WeakDirection>,
}

/// Adjusts `start` over the parameters of `candidates` that the data
/// determine, against the residual `blocks`, with the whitening fixed at
/// `start`, every parameter's prior centred on its value in `nominal` (what
/// the session knew before any data). A parameter it holds is put back
/// there: an earlier step with other data may have moved it, and its prior
/// σ is about the nominal value.
///
/// # Errors
/// [`CalibrationError::NotConverged`] naming `step`, the parameters that
/// moved most and the readings with the largest residuals.
pub fn adjust(
    input: &CalibrationInput,
    start: State,
    nominal: &State,
    candidates: &[Param],
    blocks: Blocks,
    step: &'static str,
) -> Result<Adjusted, CalibrationError> {
    let whitening = Whitening::at(input, &start)?;
    let data_only = Problem {
        input,
        params: candidates,
        blocks,
        whitening: &whitening,
        nominal: None,
    };
    let (keep, selection) = select(data_only.evaluate(&start).jtj(), candidates);
    let estimated: Vec<Param> = keep.iter().map(|&i| candidates[i]).collect();
    let start = (0..candidates.len())
        .filter(|i| !keep.contains(i))
        .fold(start, |s, i| {
            let p = candidates[i];
            let back = difference(&s, nominal, &[p])[0];
            s.perturbed(p, back)
        });
    let problem = Problem {
        params: &estimated,
        nominal: Some(nominal),
        ..data_only
    };
    let at = problem.evaluate(&start);
    let Ok(out) = minimise(&problem, start.clone(), at, &DAMPING, MAX_TRIALS);
    if !out.stop.converged() {
        return Err(CalibrationError::NotConverged {
            step,
            trials: out.trials,
            stop: format!("{:?}", out.stop),
            detail: failure_detail(input, &estimated, blocks, &start, &out.params),
        });
    }
    let held: Vec<Param> = (0..candidates.len())
        .filter(|i| !keep.contains(i))
        .map(|i| candidates[i])
        .collect();
    let params: Vec<Param> = estimated.iter().chain(&held).copied().collect();
    let full = Problem {
        params: &params,
        ..problem
    }
    .evaluate(&out.params);
    let covariance = consider_covariance(full.jtj(), estimated.len(), &held).ok_or_else(|| {
        CalibrationError::NotConverged {
            step,
            trials: out.trials,
            stop: "the normal matrix of the estimated parameters is singular".into(),
            detail: String::new(),
        }
    })?;
    // tr(P (N + P)⁻¹) over the estimated parameters: the share their
    // priors take, which the data's χ² does not pay for.
    let prior_share: f64 = estimated
        .iter()
        .enumerate()
        .filter_map(|(k, p)| p.prior_std().map(|sd| covariance[(k, k)] / (sd * sd)))
        .sum();
    let taken = estimated.len() as f64 - prior_share;
    let weak = weak_directions(&covariance, &params[..estimated.len()]);
    let bend = curvature(&problem, &held, &out.params, &covariance);
    let covariance = covariance + bend;
    Ok(Adjusted {
        state: out.params,
        selection,
        params,
        covariance,
        chi2: full.cost() - full.prior_cost,
        prior_chi2: full.prior_cost,
        dof: (full.residuals as f64 - taken).round().max(0.0) as usize,
        trials: out.trials,
        stop: out.stop,
        weak,
    })
}

/// `[[N⁻¹ + S Σ Sᵀ, −S Σ], [−Σ Sᵀ, Σ]]` with `S = N_ee⁻¹ N_eh` and `Σ`
/// the held parameters' prior variances: the estimated parameters' error
/// from noise and from the held ones being off by their prior σ.
fn consider_covariance(n: &DMatrix<f64>, n_est: usize, held: &[Param]) -> Option<DMatrix<f64>> {
    let total = n.nrows();
    let e: Vec<usize> = (0..n_est).collect();
    let h: Vec<usize> = (n_est..total).collect();
    let inv = submatrix(n, &e, &e).cholesky()?.inverse();
    let s = &inv * submatrix(n, &e, &h);
    let sigma = DMatrix::from_diagonal(&DVector::from_iterator(
        held.len(),
        held.iter().map(|p| p.prior_std().unwrap_or(0.0).powi(2)),
    ));
    let cov_ee = &inv + &s * &sigma * s.transpose();
    let cov_eh = -(&s * &sigma);
    let mut c = DMatrix::zeros(total, total);
    c.view_mut((0, 0), (n_est, n_est)).copy_from(&cov_ee);
    c.view_mut((0, n_est), (n_est, held.len()))
        .copy_from(&cov_eh);
    c.view_mut((n_est, 0), (held.len(), n_est))
        .copy_from(&cov_eh.transpose());
    c.view_mut((n_est, n_est), (held.len(), held.len()))
        .copy_from(&sigma);
    Some(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::station::Dof;

    #[test]
    fn the_consider_covariance_adds_the_held_parameters_effect() {
        // y = a + b with b held at σ_b: a's σ² is 1/N_aa + σ_b² and a, b
        // are anticorrelated by exactly −σ_b².
        let n = DMatrix::from_row_slice(2, 2, &[4.0, 4.0, 4.0, 4.0]);
        let held = [Param::Station(Dof::ScreenPitch)];
        let c = consider_covariance(&n, 1, &held).unwrap();
        let s2 = 2.7e-5_f64.powi(2);
        assert!((c[(0, 0)] - (0.25 + s2)).abs() < 1e-15);
        assert!((c[(0, 1)] + s2).abs() < 1e-20);
        assert!((c[(1, 1)] - s2).abs() < 1e-20);
    }
}
