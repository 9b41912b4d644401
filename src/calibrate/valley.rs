//! The second moment a curved valley adds to the covariance.
//!
//! Along a weakly determined direction ([`super::weak`]) the posterior is
//! not the ellipse the linearisation draws: moving the camera ten
//! millimetres along its line of sight while the focal length follows also
//! turns it, and the combination that the data pin to 1e-7 rad (where the
//! camera points against where it stands) follows a curved path, not the
//! tangent line. Measured on the narrow-field sessions, the truth
//! then lies tens of linear σ off the estimate in those tight
//! combinations, although every parameter alone is within its σ.
//!
//! So the valley's own path is traced: from the estimate `x̂`, step to
//! `x̂ ± d` (`d` the direction's 1 σ change) and let the tight
//! combinations settle (a few Gauss–Newton steps constrained to keep the
//! coordinates along every long direction, this one and the others). The
//! two end points' mean offset from `x̂` is `q = σ² c`, `c` the path's
//! curvature: with the position along the valley `s ~ N(0, σ²)`, the
//! error's second-order part `s² c` has second moment `E[s⁴] c cᵀ =
//! 3 q qᵀ`, added to the covariance. `q` lies along the tight
//! combinations, so the long directions' own σ stay the linear ones, which
//! the soak measures right (issue 35's narrow sessions, 40 seeds: mean
//! (error/σ)² of camera.z 1.06; 0.40 when the settling could also move
//! along the other long directions, whose bend into one another then
//! landed on their diagonal). What it covers is what the χ² of the truth
//! against the covariance measures.

use nalgebra::{DMatrix, DVector};

use super::adjust::Problem;
use super::params::{difference, State};
use crate::kernels::lm::{LeastSquares, Linearisation};

/// Directions whose σ is above this fraction of their prior are traced.
/// Not only the weak ones (σ above `1/√2` of the prior): a direction the
/// data narrow to a fifth of its prior may still be millimetres long, and
/// its curvature shows in the tight combinations all the same; below a
/// tenth the term `σ² c` is a hundredth of the weak ones' and the
/// evaluations (six a direction) are not worth it.
const TRACED_RATIO: f64 = 0.1;

/// Constrained Gauss–Newton steps per end point: the other combinations
/// are well determined and nearly linear, so the first step lands to a few
/// per cent and the second to rounding.
const SETTLE_STEPS: usize = 3;

/// `Σ 3 q qᵀ` over the long directions ([`TRACED_RATIO`]) of `covariance` (over `problem`'s
/// parameters first, then any held ones, which get no term), at the
/// adjustment's end `at`.
pub(super) fn curvature(
    problem: &Problem<'_>,
    at: &State,
    covariance: &DMatrix<f64>,
) -> DMatrix<f64> {
    let total = covariance.nrows();
    let params = problem.params;
    let n = params.len();
    let mut out = DMatrix::zeros(total, total);
    let sd: Vec<Option<f64>> = params.iter().map(|p| p.prior_std()).collect();
    let idx: Vec<usize> = (0..n).filter(|&k| sd[k].is_some()).collect();
    if idx.is_empty() {
        return out;
    }
    let m = idx.len();
    let scaled = DMatrix::from_fn(m, m, |a, b| {
        let (i, j) = (idx[a], idx[b]);
        covariance[(i, j)] / (sd[i].unwrap_or(1.0) * sd[j].unwrap_or(1.0))
    });
    let eig = scaled.symmetric_eigen();
    let precision = problem.evaluate(at).jtj().clone();
    // Every long direction at its 1 σ change.
    let long: Vec<DVector<f64>> = (0..m)
        .filter(|&k| eig.eigenvalues[k] > TRACED_RATIO * TRACED_RATIO)
        .map(|k| {
            let s = eig.eigenvalues[k].sqrt();
            let mut d = DVector::zeros(n);
            for (a, &i) in idx.iter().enumerate() {
                d[i] = eig.eigenvectors[(a, k)] * s * sd[i].unwrap_or(0.0);
            }
            d
        })
        .collect();
    if long.is_empty() {
        return out;
    }
    // The coordinates along every long direction that the settling keeps:
    // dᵀH (x − x̂), H the posterior precision, so that the settling moves
    // only the tight combinations (H-orthogonal to all of them). Letting
    // it move along the other long directions as well would measure their
    // bend into one another, where a Gauss–Newton step is as poor as the
    // valley is curved, and put it on the long directions' own diagonal,
    // which the linear covariance already covers (issue 35's narrow
    // sessions: σ(camera.z) 1.23 mm linear, 2.08 with such a term, the
    // actual scatter 1.31 mm over 40 seeds).
    let keep = DMatrix::from_columns(&long.iter().map(|d| &precision * d).collect::<Vec<_>>());
    for d in &long {
        let ends: Vec<DVector<f64>> = [1.0, -1.0]
            .iter()
            .filter_map(|sign| settle(problem, at, &(d * *sign), &keep))
            .collect();
        if ends.len() < 2 {
            continue;
        }
        let q = (&ends[0] + &ends[1]) * 0.5;
        for i in 0..n {
            for j in 0..n {
                out[(i, j)] += 3.0 * q[i] * q[j];
            }
        }
    }
    out
}

/// `x̂ + d`, settled along every combination H-orthogonal to the long
/// directions (the constraints `Kᵀ y = 0` on each step `y`, `K`'s columns
/// `H d_k`); its offset from `x̂` in the parameters' coordinates. `None`
/// where a step does not give a model.
fn settle(
    problem: &Problem<'_>,
    at: &State,
    d: &DVector<f64>,
    keep: &DMatrix<f64>,
) -> Option<DVector<f64>> {
    let mut x = problem.moved(at, d).ok()?;
    for _ in 0..SETTLE_STEPS {
        let normal = problem.evaluate(&x);
        if !normal.cost().is_finite() {
            return None;
        }
        // min ½ yᵀA y − gᵀy subject to Kᵀy = 0: y = A⁻¹(g − K μ),
        // μ = (KᵀA⁻¹K)⁻¹ KᵀA⁻¹g.
        let chol = normal.jtj().clone().cholesky()?;
        let ag = chol.solve(normal.jtr());
        let ak = chol.solve(keep);
        let mu = (keep.transpose() * &ak)
            .cholesky()?
            .solve(&(keep.transpose() * &ag));
        let y = ag - ak * mu;
        x = problem.moved(&x, &y).ok()?;
    }
    Some(DVector::from_vec(difference(at, &x, problem.params)))
}
