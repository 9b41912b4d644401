//! The fits of the signal model: Levenberg–Marquardt on the shared loop
//! ([`crate::kernels::lm`]) with the spectral fits' damping schedule and
//! convergence tests, and the single Gauss–Newton step of a warm start.

use std::convert::Infallible;

use nalgebra::{DMatrix, DVector};

use super::{Normal, Params, Samples};
use crate::kernels::lm::{self, Damping, LeastSquares, Linearisation};
use crate::kernels::SmallCholesky;

/// Outcome of a Levenberg–Marquardt fit.
#[derive(Debug, Clone)]
pub struct Fit {
    /// Final parameters.
    pub params: Params,
    /// Residual sum of squares.
    pub rss: f64,
    /// JᵀJ at the solution (Fisher information × σ²).
    pub jtj: DMatrix<f64>,
    /// Iterations taken.
    pub iterations: usize,
    /// Whether the convergence test was met.
    pub converged: bool,
}

impl Fit {
    /// The noise variance its residuals estimate, σ̂² = RSS/(N − p), for
    /// `n` samples.
    pub fn sigma2(&self, n: usize) -> f64 {
        self.rss / dof(n, &self.params)
    }
}

/// Degrees of freedom N − p (at least 1) of `p` fitted to `n` samples.
fn dof(n: usize, p: &Params) -> f64 {
    n.saturating_sub(p.len()).max(1) as f64
}

/// The decrease of the RSS below which a fit has converged: [`RSS_TOL`] of
/// it, or [`CHI2_TOL`] in χ² at the residuals' own noise level (`dof`
/// degrees of freedom); never 0, so that an exact fit stops too.
fn stop_tolerance(rss: f64, dof: f64) -> f64 {
    (RSS_TOL * rss).max(CHI2_TOL * rss / dof).max(1e-300)
}

/// Convergence: a step below 1e-5 screen px in every (u, v) (three decades
/// under the noise-free accuracy goal of 0.01 px) or a relative RSS change
/// below 1e-11.
const STEP_TOL_PX: f64 = 1e-5;
const RSS_TOL: f64 = 1e-11;
/// Convergence, statistically: the step lowered χ² = RSS/σ̂² (σ̂² = RSS/(N − p),
/// the residuals' own noise level) by less than this. A Gauss–Newton step
/// that lowers χ² by ε moves the parameters by ~√ε of their standard
/// deviations, so 1e-3 leaves ~0.03σ — a 0.05 % change of the error RMS —
/// and stops fits of a wrong model (one reflection of two), whose RSS creeps
/// down linearly, after a few steps instead of ~15.
const CHI2_TOL: f64 = 1e-3;

/// Most parameters of a model (three reflections).
use super::MAX_PARAMS;

/// The Cholesky factorisation of a model's JᵀJ, on the stack.
pub(crate) type ParamCholesky = SmallCholesky<MAX_PARAMS>;

/// The spectral fits' damping schedule for the shared loop
/// ([`crate::kernels::lm`], whose policy it parameterises).
///
/// A fit starts from the periodogram's peaks or the pair scan, within a
/// fraction of a fringe of the optimum, but the model is a sum of cosines of
/// the screen points: a full Gauss–Newton step there can overshoot into a
/// neighbouring fringe's basin, along the nearly degenerate directions of two
/// close reflections above all. So the first step is damped lightly, λ =
/// 1e-3: a direction whose curvature is μ relative to the diagonal moves by
/// μ/(μ + λ) of its Gauss–Newton step — the well-determined ones (μ ~ 1) by
/// 99.9 %, the nearly degenerate ones (μ ≲ 1e-3) by half or less. An evaluation
/// is one pass over the pixel's samples and a fit takes 3–6 of them, so λ
/// moves gently: ×4 after a rejected step (its direction was right to first
/// order; four times the damping shortens the poorly modelled part without
/// discarding it), ÷3 after an accepted one (two accepted steps undo a
/// rejection). The predicted-decrease stop trusts the linearisation up to
/// λ = 1e-2: from the start and after one rejection (4e-3), not after two
/// (1.6e-2), when the model has just mispredicted twice. At λ = 1e12 a step
/// is 1e-12 of a scaled gradient step, below rounding of every parameter:
/// no downhill step exists, a minimum to rounding. Floor 1e-12:
/// Gauss–Newton to rounding.
pub const DAMPING: Damping = Damping {
    start: 1e-3,
    up: 4.0,
    down: 3.0,
    floor: 1e-12,
    cap: 1e12,
    trust_prediction_below: Some(1e-2),
    stall: None,
};

impl Linearisation for Normal {
    fn cost(&self) -> f64 {
        self.rss
    }

    fn jtj(&self) -> &DMatrix<f64> {
        &self.jtj
    }

    fn jtr(&self) -> &DVector<f64> {
        &self.jtr
    }
}

/// One pixel's fit as a problem of the shared loop.
struct PixelProblem<'a, S: ?Sized> {
    data: &'a S,
    /// Reflections of the model fitted.
    k: usize,
    /// Its degrees of freedom, N − p.
    dof: f64,
}

impl<S: Samples + ?Sized> LeastSquares for PixelProblem<'_, S> {
    type Params = Params;
    type Normal = Normal;
    type Error = Infallible;

    fn evaluate(&self, p: &Params) -> Normal {
        self.data.normal(p)
    }

    fn moved(&self, p: &Params, step: &DVector<f64>) -> Result<Params, Infallible> {
        Ok(p.add(step))
    }

    /// Every screen point moved by less than [`STEP_TOL_PX`].
    fn small_step(&self, step: &DVector<f64>) -> bool {
        (0..self.k).all(|j| {
            let u = 1 + self.k + 2 * j;
            step[u].abs() < STEP_TOL_PX && step[u + 1].abs() < STEP_TOL_PX
        })
    }

    fn decrease_tolerance(&self, at: &Normal) -> Option<f64> {
        Some(stop_tolerance(at.rss, self.dof))
    }
}

/// Levenberg–Marquardt from `start` on the shared loop
/// ([`crate::kernels::lm::minimise`], schedule [`DAMPING`]), at most
/// `max_iter` evaluated steps.
///
/// Converged when a step lowered χ² by less than [`CHI2_TOL`] (or the RSS
/// by [`RSS_TOL`] relative, or moved every point by less than
/// [`STEP_TOL_PX`]) — or when the next step, at a damping where the
/// linearisation is trusted, is predicted to: then the current point is the
/// fit and the evaluation that would only confirm it is saved (one of the
/// 3–6 per fit). `iterations` counts the evaluated steps.
pub fn levenberg_marquardt<S: Samples + ?Sized>(data: &S, start: Params, max_iter: usize) -> Fit {
    levenberg_marquardt_at(data, start, data.normal(&start), max_iter)
}

/// One Gauss–Newton step from `start`, evaluated: the fit after it, the
/// next step from there and the decrease the linearisation predicts for it
/// (`Jᵀr · (JᵀJ)⁻¹Jᵀr`), and Jᵀr after it (with the fit's RSS and JᵀJ,
/// the normal equations from which [`levenberg_marquardt_at`] goes on).
/// `None` when the step raises the RSS or JᵀJ is singular.
pub fn gauss_newton_step<S: Samples + ?Sized>(
    data: &S,
    start: Params,
) -> Option<(Fit, DVector<f64>, f64, DVector<f64>)> {
    let ne = data.normal(&start);
    if !ne.rss.is_finite() {
        return None;
    }
    let step = ParamCholesky::new(&ne.jtj)?.solve(&ne.jtr);
    let p = start.add(&step);
    let at = data.normal(&p);
    if !(at.rss.is_finite() && at.rss <= ne.rss) {
        return None;
    }
    let next = ParamCholesky::new(&at.jtj)?.solve(&at.jtr);
    let remaining = at.jtr.dot(&next).max(0.0);
    let converged = remaining <= stop_tolerance(at.rss, dof(data.count(), &p));
    Some((
        Fit {
            params: p,
            rss: at.rss,
            jtj: at.jtj,
            iterations: 1,
            converged,
        },
        next,
        remaining,
        at.jtr,
    ))
}

/// [`levenberg_marquardt`] from `start` whose normal equations `at_start`
/// are already evaluated (the end of a [`gauss_newton_step`]): the
/// evaluation is not repeated.
pub fn levenberg_marquardt_at<S: Samples + ?Sized>(
    data: &S,
    start: Params,
    at_start: Normal,
    max_iter: usize,
) -> Fit {
    let problem = PixelProblem {
        data,
        k: start.k,
        dof: dof(data.count(), &start),
    };
    let Ok(out) = lm::minimise(&problem, start, at_start, &DAMPING, max_iter);
    Fit {
        params: out.params,
        rss: out.normal.rss,
        jtj: out.normal.jtj,
        iterations: out.trials,
        converged: out.stop.converged(),
    }
}
