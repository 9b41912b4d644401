//! The one damped least-squares loop (Levenberg–Marquardt) over a problem's
//! normal equations, shared by the spectral stage's per-pixel fits and the
//! surface solvers.
//!
//! # Policy
//! A step solves `(JᵀJ + λ D) δ = Jᵀr`, `D = diag(JᵀJ)` (Marquardt's
//! scaling; [`solve_damped`]). Scaling by the diagonal makes the damping
//! independent of the parameters' units — the spectral model mixes counts,
//! screen pixels and a falloff per τ², the surfaces Zernike terms whose
//! sensitivities differ by decades — and damps most the directions whose
//! curvature is small against the diagonal, i.e. nearly degenerate
//! combinations (two close reflections, correlated terms), which is where a
//! Gauss–Newton step from a poor start goes wrong.
//!
//! A trial step is accepted when its cost (residual sum of squares) is
//! finite and not above the current one (and the problem deems the two
//! comparable: [`LeastSquares::comparable`]); then λ is divided by
//! [`Damping::down`] (not below [`Damping::floor`]), else multiplied by
//! [`Damping::up`]. Past [`Damping::cap`] no downhill step exists at any
//! damping worth the name: the point is a minimum to rounding
//! ([`Stop::Floor`]). A damped system that cannot be factored raises λ the
//! same way, without an evaluation ([`Stop::Singular`] past the cap).
//!
//! Converged ([`Stop`]): an accepted step the problem calls small
//! ([`LeastSquares::small_step`]); an accepted step that lowered the cost
//! by at most the problem's tolerance ([`LeastSquares::decrease_tolerance`]);
//! or, where the schedule trusts the linearisation
//! ([`Damping::trust_prediction_below`]), a next step whose predicted
//! decrease `2 δᵀJᵀr − δᵀJᵀJ δ` (the Gauss–Newton model's own, which near
//! the minimum is the actual one) is below that tolerance: the current
//! point is then the fit and the evaluation that would only confirm it is
//! saved.
//!
//! Stalled ([`Stop::Stalled`], where the schedule asks for it with
//! [`Damping::stall`]): over the last `window` evaluated trials the cost
//! fell by less than `decrease` in all. That is the stall test that
//! replaces a fixed trial count on a problem with a curved, weakly
//! determined valley, where LM alternates accepted and rejected steps and
//! crawls: the loop stops when the crawl no longer buys anything, however
//! many trials it has taken, and keeps going while it does (the trial
//! limit is then a guard against a bug, not the convergence rule). Whether
//! a stall is a minimum is the problem's to say: with the cost in χ² units
//! a total fall well under 1 over many trials moves the point by a small
//! fraction of its σ along any direction the data see.
//!
//! # Schedules
//! The scaling and the rules above are one for both users; the numbers of
//! the schedule ([`Damping`]) are each user's, because the two start in
//! different places and pay differently for an evaluation: the spectral
//! fits start near a cosine model's optimum from a periodogram (a full
//! Gauss–Newton step can jump a fringe, and an evaluation is a pass over
//! one pixel's samples), the surface solvers from a flat plate on a nearly
//! linear problem (Gauss–Newton is right almost always, and an evaluation
//! traces every measured path). Each schedule is written and justified
//! beside its problem: `solve::spectral::model::DAMPING` and
//! `solve::surfaces::lm::DAMPING`.

use nalgebra::{DMatrix, DVector};

use super::cholesky::SmallCholesky;

/// Systems up to this size are factored on the stack ([`SmallCholesky`]):
/// the spectral model's largest, three reflections with 11 parameters.
/// Larger ones (the surfaces' Zernike terms) go to nalgebra.
const STACK_DIM: usize = 11;

/// The damping schedule. See the [module documentation](self) for the
/// policy it parameterises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Damping {
    /// λ of the first step.
    pub start: f64,
    /// Factor λ is multiplied by after a rejected step (or a singular system).
    pub up: f64,
    /// Divisor of λ after an accepted step.
    pub down: f64,
    /// Smallest λ.
    pub floor: f64,
    /// λ beyond which no step is tried.
    pub cap: f64,
    /// λ up to which the predicted decrease of the next step is trusted to
    /// stop the loop; `None`: never (every step is evaluated).
    pub trust_prediction_below: Option<f64>,
    /// The stall test: stop when the last `window` trials lowered the cost
    /// by less than `decrease` in all; `None`: no stall test.
    pub stall: Option<Stall>,
}

/// The stall test of a [`Damping`] schedule (see the
/// [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stall {
    /// Trials looked back over.
    pub window: usize,
    /// The total fall of the cost below which the loop has stalled.
    pub decrease: f64,
}

/// One linearisation of a problem: what the loop reads of its normal
/// equations.
pub trait Linearisation {
    /// The cost: residual sum of squares (χ² for σ-weighted residuals).
    fn cost(&self) -> f64;
    /// `JᵀJ`, J the Jacobian of the model.
    fn jtj(&self) -> &DMatrix<f64>;
    /// `Jᵀr`, r = data − model: the Gauss–Newton step solves `JᵀJ δ = Jᵀr`.
    fn jtr(&self) -> &DVector<f64>;
}

/// Normal equations and nothing more: the [`Linearisation`] of a problem
/// that keeps no other state at a point (a problem that does, e.g. a
/// prior's part of the cost, implements the trait on its own struct).
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEquations {
    /// The cost (residual sum of squares, or χ²).
    pub cost: f64,
    /// `JᵀJ`.
    pub jtj: DMatrix<f64>,
    /// `Jᵀr`.
    pub jtr: DVector<f64>,
}

impl Linearisation for NormalEquations {
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

/// A least-squares problem for [`minimise`].
pub trait LeastSquares {
    /// The parameters.
    type Params;
    /// A linearisation at a point.
    type Normal: Linearisation;
    /// What can go wrong when moving the parameters.
    type Error;

    /// The normal equations at `p`.
    fn evaluate(&self, p: &Self::Params) -> Self::Normal;
    /// `p` moved by `step` (in the column order of [`Linearisation::jtj`]).
    ///
    /// # Errors
    /// Where the moved parameters do not describe a model.
    fn moved(&self, p: &Self::Params, step: &DVector<f64>) -> Result<Self::Params, Self::Error>;
    /// Whether the cost at `trial` can be compared with that at `current`
    /// (e.g. both sum the same residuals).
    fn comparable(&self, _current: &Self::Normal, _trial: &Self::Normal) -> bool {
        true
    }
    /// Whether an accepted `step` is small enough to stop.
    fn small_step(&self, step: &DVector<f64>) -> bool;
    /// The decrease of the cost below which a step from `at` is negligible;
    /// `None`: the problem judges convergence by the step alone.
    fn decrease_tolerance(&self, _at: &Self::Normal) -> Option<f64> {
        None
    }
}

/// Why [`minimise`] stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stop {
    /// An accepted step was small ([`LeastSquares::small_step`]).
    SmallStep,
    /// An accepted step lowered the cost by at most the tolerance.
    SmallDecrease {
        /// The decrease of the cost.
        decrease: f64,
    },
    /// The next step, at a trusted damping, was predicted to lower the cost
    /// by at most the tolerance; it was not evaluated.
    PredictedSmall {
        /// The predicted decrease.
        predicted: f64,
    },
    /// No step lowered the cost up to the damping cap: a minimum to rounding.
    Floor,
    /// The damped system could not be factored up to the damping cap.
    Singular,
    /// The last [`Stall::window`] trials lowered the cost by less than
    /// [`Stall::decrease`] in all.
    Stalled {
        /// The fall of the cost over the window.
        decrease: f64,
    },
    /// The trial limit was reached.
    TrialLimit,
}

impl Stop {
    /// Whether the point is a minimum: every stop but [`Stop::Singular`]
    /// and [`Stop::TrialLimit`].
    pub fn converged(&self) -> bool {
        !matches!(self, Stop::Singular | Stop::TrialLimit)
    }
}

/// Where [`minimise`] ended.
#[derive(Debug, Clone)]
pub struct Outcome<P, N> {
    /// The last accepted parameters.
    pub params: P,
    /// The normal equations there.
    pub normal: N,
    /// Trial steps evaluated.
    pub trials: usize,
    /// Why it stopped.
    pub stop: Stop,
    /// The last step solved (accepted or rejected), if any.
    pub last_step: Option<DVector<f64>>,
}

/// Solves `(A + λ diag A) δ = g` (a zero diagonal entry damped as 1e-300);
/// `None` when the damped matrix is not positive definite.
pub fn solve_damped(a: &DMatrix<f64>, lambda: f64, g: &DVector<f64>) -> Option<DVector<f64>> {
    let n = a.nrows();
    let damped = |i: usize| a[(i, i)] + lambda * a[(i, i)].max(1e-300);
    if n <= STACK_DIM {
        let entry = |i: usize, j: usize| if i == j { damped(i) } else { a[(i, j)] };
        SmallCholesky::<STACK_DIM>::from_fn(n, entry).map(|c| c.solve(g))
    } else {
        let mut m = a.clone();
        for i in 0..n {
            m[(i, i)] = damped(i);
        }
        m.cholesky().map(|c| c.solve(g))
    }
}

/// Levenberg–Marquardt from `start` (with `at_start`, its normal
/// equations), at most `max_trials` evaluated steps, on the schedule
/// `damping`; the policy is the [module's](self).
///
/// # Errors
/// The problem's, where a step does not give a model
/// ([`LeastSquares::moved`]).
pub fn minimise<L: LeastSquares>(
    problem: &L,
    start: L::Params,
    at_start: L::Normal,
    damping: &Damping,
    max_trials: usize,
) -> Result<Outcome<L::Params, L::Normal>, L::Error> {
    let mut p = start;
    let mut cur = at_start;
    let mut lambda = damping.start;
    let mut trials = 0;
    let mut last_step = None;
    // The cost after each trial (accepted or not: the current one), kept
    // only for a stall test: the spectral stage runs this loop per pixel,
    // and a Vec::new() costs it no allocation.
    let mut history = Vec::new();
    if damping.stall.is_some() {
        history.push(cur.cost());
    }
    let stop = loop {
        if let Some(st) = damping.stall {
            if history.len() > st.window {
                let decrease = history[history.len() - 1 - st.window] - cur.cost();
                if decrease < st.decrease {
                    break Stop::Stalled { decrease };
                }
            }
        }
        if trials >= max_trials {
            break Stop::TrialLimit;
        }
        let Some(step) = solve_damped(cur.jtj(), lambda, cur.jtr()) else {
            lambda *= damping.up;
            if lambda > damping.cap {
                break Stop::Singular;
            }
            continue;
        };
        let trusted = damping.trust_prediction_below.is_some_and(|t| lambda <= t);
        if trusted && cur.cost().is_finite() {
            if let Some(tol) = problem.decrease_tolerance(&cur) {
                let predicted = 2.0 * step.dot(cur.jtr()) - (cur.jtj() * &step).dot(&step);
                if predicted <= tol {
                    break Stop::PredictedSmall { predicted };
                }
            }
        }
        trials += 1;
        let trial_p = problem.moved(&p, &step)?;
        let trial = problem.evaluate(&trial_p);
        let downhill = trial.cost().is_finite() && trial.cost() <= cur.cost();
        if downhill && problem.comparable(&cur, &trial) {
            let decrease = cur.cost() - trial.cost();
            let small_step = problem.small_step(&step);
            let small_decrease = problem
                .decrease_tolerance(&trial)
                .is_some_and(|tol| decrease <= tol);
            p = trial_p;
            cur = trial;
            lambda = (lambda / damping.down).max(damping.floor);
            last_step = Some(step);
            if damping.stall.is_some() {
                history.push(cur.cost());
            }
            if small_step {
                break Stop::SmallStep;
            }
            if small_decrease {
                break Stop::SmallDecrease { decrease };
            }
        } else {
            last_step = Some(step);
            if damping.stall.is_some() {
                history.push(cur.cost());
            }
            lambda *= damping.up;
            if lambda > damping.cap {
                break Stop::Floor;
            }
        }
    };
    Ok(Outcome {
        params: p,
        normal: cur,
        trials,
        stop,
        last_step,
    })
}

#[cfg(test)]
#[path = "lm_tests.rs"]
mod tests;
