//! Tests of the damped least-squares loop on problems with known minima.

use std::convert::Infallible;

use super::*;

/// Rosenbrock's function as least squares, `r = (10 (x₂ − x₁²), 1 − x₁)`:
/// the curved valley that defeats an undamped Gauss–Newton step from the
/// classic start (−1.2, 1); the minimum is (1, 1) with cost 0 (closed form).
struct Rosenbrock;

impl LeastSquares for Rosenbrock {
    type Params = [f64; 2];
    type Normal = NormalEquations;
    type Error = Infallible;

    fn evaluate(&self, p: &[f64; 2]) -> NormalEquations {
        // Residuals as data − model with data 0: r = −f, J = ∂f.
        let f = DVector::from_column_slice(&[10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]]);
        let j = DMatrix::from_row_slice(2, 2, &[-20.0 * p[0], 10.0, -1.0, 0.0]);
        let r = -&f;
        NormalEquations {
            cost: f.norm_squared(),
            jtj: j.transpose() * &j,
            jtr: j.transpose() * r,
        }
    }

    fn moved(&self, p: &[f64; 2], step: &DVector<f64>) -> Result<[f64; 2], Infallible> {
        Ok([p[0] + step[0], p[1] + step[1]])
    }

    fn small_step(&self, step: &DVector<f64>) -> bool {
        step.amax() < 1e-12
    }

    fn decrease_tolerance(&self, at: &NormalEquations) -> Option<f64> {
        Some(1e-30 * at.cost.max(1e-300))
    }
}

const SCHEDULE: Damping = Damping {
    start: 1e-3,
    up: 4.0,
    down: 3.0,
    floor: 1e-12,
    cap: 1e12,
    trust_prediction_below: Some(1e-2),
    stall: None,
};

fn run(max_trials: usize) -> Outcome<[f64; 2], NormalEquations> {
    let start = [-1.2, 1.0];
    let at = Rosenbrock.evaluate(&start);
    let Ok(out) = minimise(&Rosenbrock, start, at, &SCHEDULE, max_trials);
    out
}

#[test]
fn finds_the_rosenbrock_minimum() {
    let out = run(200);
    assert!(out.stop.converged(), "{:?}", out.stop);
    // Exact minimum (1, 1); the loop stops at rounding, 1e-10 leaves room
    // for the square root of machine precision a flat valley floor allows.
    assert!((out.params[0] - 1.0).abs() < 1e-10, "{:?}", out.params);
    assert!((out.params[1] - 1.0).abs() < 1e-10, "{:?}", out.params);
    assert!(out.normal.cost < 1e-20);
    // The cost never rises: each accepted step is downhill.
    assert!(out.trials > 1 && out.trials < 200);
}

#[test]
fn stops_at_the_trial_limit() {
    let out = run(3);
    assert_eq!(out.stop, Stop::TrialLimit);
    assert_eq!(out.trials, 3);
    assert!(!out.stop.converged());
}

#[test]
fn a_singular_system_stops_without_evaluating() {
    // A NaN curvature cannot be factored at any damping.
    let at = NormalEquations {
        cost: 1.0,
        jtj: DMatrix::from_element(2, 2, f64::NAN),
        jtr: DVector::zeros(2),
    };
    let Ok(out) = minimise(&Rosenbrock, [0.0, 0.0], at, &SCHEDULE, 10);
    assert_eq!(out.stop, Stop::Singular);
    assert_eq!(out.trials, 0);
    assert!(out.last_step.is_none());
}

#[test]
fn damped_solve_is_marquardts() {
    // (A + λ diag A) δ = g against the matrix written out.
    let a = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
    let g = DVector::from_column_slice(&[1.0, 2.0]);
    let lambda = 0.5;
    let m = DMatrix::from_row_slice(2, 2, &[6.0, 1.0, 1.0, 4.5]);
    let want = m.cholesky().unwrap().solve(&g);
    let got = solve_damped(&a, lambda, &g).unwrap();
    assert!((got - &want).amax() < 1e-15);
    // Beyond the stack size, through nalgebra: the same formula.
    let n = STACK_DIM + 1;
    let big = DMatrix::from_fn(n, n, |i, j| if i == j { 2.0 + i as f64 } else { 0.1 });
    let rhs = DVector::from_element(n, 1.0);
    let mut damped = big.clone();
    for i in 0..n {
        damped[(i, i)] *= 1.0 + lambda;
    }
    let want = damped.cholesky().unwrap().solve(&rhs);
    assert!((solve_damped(&big, lambda, &rhs).unwrap() - want).amax() < 1e-14);
}

#[test]
fn a_crawl_stops_at_the_stall_test_and_not_before() {
    // Rosenbrock from its classic start: the cost falls from 24.2 to 0
    // along the curved valley. A stall test whose window's fall must reach
    // 1e6 (far above any fall there is) stops at its first chance, after
    // exactly `window` trials; one asking for 1e-300 never fires, and the
    // loop converges as without it.
    let start = [-1.2, 1.0];
    let stalled = Damping {
        stall: Some(Stall {
            window: 5,
            decrease: 1e6,
        }),
        ..SCHEDULE
    };
    let Ok(out) = minimise(
        &Rosenbrock,
        start,
        Rosenbrock.evaluate(&start),
        &stalled,
        200,
    );
    assert!(matches!(out.stop, Stop::Stalled { .. }), "{:?}", out.stop);
    assert_eq!(out.trials, 5);
    assert!(out.stop.converged());
    let patient = Damping {
        stall: Some(Stall {
            window: 5,
            decrease: 1e-300,
        }),
        ..SCHEDULE
    };
    let Ok(out) = minimise(
        &Rosenbrock,
        start,
        Rosenbrock.evaluate(&start),
        &patient,
        200,
    );
    assert!(!matches!(out.stop, Stop::Stalled { .. }), "{:?}", out.stop);
    assert!((out.params[0] - 1.0).abs() < 1e-10);
}
