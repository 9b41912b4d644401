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
//! So the valley's own path is traced. The error's first-order part is a
//! sum of independent N(0, 1) variables `s_i` times generators `g_i`: the
//! long directions of the noise's covariance `(N + P)⁻¹` (σ above a
//! thirtieth of the prior) at 1 σ, and each held parameter off by its prior σ with
//! the estimated ones following to first order (the consider covariance's
//! column). From the estimate `x̂`, step along a generator or a pair of
//! them and let the tight combinations settle (a Gauss–Newton step
//! constrained to keep the coordinates along every long direction); the
//! settled offsets' even parts give the second-order part of the error,
//! `y = Σ_ij Q_ij s_i s_j`, whose second moment `m mᵀ + 2 Σ_ij Q_ij Q_ijᵀ`
//! (`m = Σ_i Q_ii`; Isserlis) is added to the covariance. `y` lies along
//! the tight combinations, so the long directions' own σ stay the linear
//! ones, which the soak measures right (issue 35's narrow sessions, 40
//! seeds: mean (error/σ)² of camera.z 1.06; 0.40 when the settling could
//! also move along the other long directions, whose bend into one another
//! then landed on their diagonal).
//!
//! The pairs are what matters: on those sessions each long direction
//! alone bends the tightest combination by 0.1 of its σ, but two of them
//! together by 4.7 σ per σ² (a turn about one axis after a turn about
//! another), and the held parameters' prior draws cross the long
//! directions as well. With only each direction's own bend (`3 q qᵀ`),
//! 19 of 40 seeds had a χ² of the truth (k = 30) at p < 0.001; with the
//! pairs and the held parameters, none (χ² 14.5–50.8, mean 28.6).

use nalgebra::{DMatrix, DVector};

use super::adjust::Problem;
use super::params::{difference, Param, State};
use crate::kernels::lm::{LeastSquares, Linearisation};

/// Directions whose σ is above this fraction of their prior are traced.
/// Not only the weak ones (σ above `1/√2` of the prior): a direction the
/// data narrow to a thirtieth of its prior may still bend a combination the
/// data pin to 1e-8 rad, in a pair with a long one. Measured on the
/// independent soak (50 sessions), mean χ²/k of the truth over the
/// directions the data decide (band 1 ± 0.053 over 500 sessions): 1.311
/// tracing down to a tenth, 1.001 to a thirtieth, 0.991 to a hundredth (at
/// twice the time); sessions failing their χ² test 16, 6 and 5 of 500.
const TRACED_RATIO: f64 = 0.03;

/// Constrained Gauss–Newton steps per end point: the other combinations
/// are well determined and nearly linear, so the first step lands to a few
/// per cent (three steps gave the same χ² of the truth to its first
/// decimal on issue 35's 40 narrow sessions, at three times the cost).
const SETTLE_STEPS: usize = 1;

/// One N(0, 1) variable of the error's first-order part: a change of the
/// estimated parameters (`est`) and of the held ones (`held`, in the order
/// of [`curvature`]'s `held`).
#[derive(Clone)]
struct Generator {
    est: DVector<f64>,
    held: DVector<f64>,
}

impl Generator {
    fn combine(&self, other: &Generator, sign: f64) -> Generator {
        Generator {
            est: &self.est + &other.est * sign,
            held: &self.held + &other.held * sign,
        }
    }
    fn neg(&self) -> Generator {
        Generator {
            est: -&self.est,
            held: -&self.held,
        }
    }
}

/// The second moment of the error's second-order part, over `problem`'s
/// parameters first, then the `held` ones (which get no term of their
/// own: they move only by their prior draw), at the adjustment's end `at`,
/// `covariance` the consider covariance over both.
pub(super) fn curvature(
    problem: &Problem<'_>,
    held: &[Param],
    at: &State,
    covariance: &DMatrix<f64>,
) -> DMatrix<f64> {
    let total = covariance.nrows();
    let params = problem.params;
    let n = params.len();
    let h = held.len();
    let mut out = DMatrix::zeros(total, total);
    if total != n + h {
        return out;
    }
    let precision = problem.evaluate(at).jtj().clone();
    let Some(posterior) = precision.clone().cholesky().map(|c| c.inverse()) else {
        return out;
    };
    let sd: Vec<Option<f64>> = params.iter().map(|p| p.prior_std()).collect();
    let idx: Vec<usize> = (0..n).filter(|&k| sd[k].is_some()).collect();
    let m = idx.len();
    let scaled = DMatrix::from_fn(m, m, |a, b| {
        let (i, j) = (idx[a], idx[b]);
        posterior[(i, j)] / (sd[i].unwrap_or(1.0) * sd[j].unwrap_or(1.0))
    });
    let eig = scaled.symmetric_eigen();
    // Every long direction of the noise's part, (N + P)⁻¹, at its 1 σ change.
    let mut gens: Vec<Generator> = (0..m)
        .filter(|&k| eig.eigenvalues[k] > TRACED_RATIO * TRACED_RATIO)
        .map(|k| {
            let s = eig.eigenvalues[k].sqrt();
            let mut d = DVector::zeros(n);
            for (a, &i) in idx.iter().enumerate() {
                d[i] = eig.eigenvectors[(a, k)] * s * sd[i].unwrap_or(0.0);
            }
            Generator {
                est: d,
                held: DVector::zeros(h),
            }
        })
        .collect();
    // The coordinates along every long direction that the settling keeps:
    // dᵀH (x − x̂), H the posterior precision, so that the settling moves
    // only the tight combinations (H-orthogonal to all of them). Letting
    // it move along the other long directions as well would measure their
    // bend into one another, where a Gauss–Newton step is as poor as the
    // valley is curved, and put it on the long directions' own diagonal,
    // which the linear covariance already covers (issue 35's narrow
    // sessions: σ(camera.z) 1.23 mm linear, 2.08 with such a term, the
    // actual scatter 1.31 mm over 40 seeds).
    let columns: Vec<DVector<f64>> = gens.iter().map(|g| &precision * &g.est).collect();
    let keep = if columns.is_empty() {
        DMatrix::zeros(n, 0)
    } else {
        DMatrix::from_columns(&columns)
    };
    let n_long = gens.len();
    // Each held parameter off by its prior σ, the estimated ones following
    // to first order (the consider covariance's column over σ).
    for (k, p) in held.iter().enumerate() {
        let Some(s) = p.prior_std().filter(|s| *s > 0.0) else {
            continue;
        };
        let mut dh = DVector::zeros(h);
        dh[k] = s;
        gens.push(Generator {
            est: DVector::from_fn(n, |i, _| covariance[(i, n + k)] / s),
            held: dh,
        });
    }
    if gens.is_empty() {
        return out;
    }
    // The error's second-order part over the generators' variables `s`
    // (independent, N(0, 1)): `y(s) = Σ_ij Q_ij s_i s_j`. `Q_ii` from the
    // even part of the settled offset at ±g_i, `Q_ij` from the even parts
    // at ±(g_i + g_j) and ±(g_i − g_j), whose difference is `4 Q_ij` (odd,
    // third-order terms cancel in each even part). Pairs of two held
    // parameters are left out: on issue 35's narrow sessions they changed
    // no χ² of the truth in its first decimal (40 seeds), and they are most
    // of the pairs (15 of 36 there, each four settlings).
    let even = |g: &Generator| -> Option<DVector<f64>> {
        let a = settle(problem, held, at, g, &keep)?;
        let b = settle(problem, held, at, &g.neg(), &keep)?;
        Some((a + b) * 0.5)
    };
    let l = gens.len();
    let mut q: Vec<Vec<Option<DVector<f64>>>> = vec![vec![None; l]; l];
    for i in 0..l {
        q[i][i] = even(&gens[i]);
    }
    for i in 0..l {
        for j in i + 1..l {
            if i >= n_long && j >= n_long {
                continue;
            }
            let (Some(plus), Some(minus)) = (
                even(&gens[i].combine(&gens[j], 1.0)),
                even(&gens[i].combine(&gens[j], -1.0)),
            ) else {
                continue;
            };
            let qij = (plus - minus) * 0.25;
            q[j][i] = Some(qij.clone());
            q[i][j] = Some(qij);
        }
    }
    // Isserlis: E[s_i s_j s_k s_l] = δ_ij δ_kl + δ_ik δ_jl + δ_il δ_jk, so
    // E[y yᵀ] = m mᵀ + 2 Σ_ij Q_ij Q_ijᵀ with m = Σ_i Q_ii (one direction
    // alone: 3 q qᵀ).
    let mut mean = DVector::zeros(n);
    let mut second = DMatrix::zeros(n, n);
    for (i, row) in q.iter().enumerate() {
        for (j, qij) in row.iter().enumerate() {
            let Some(qij) = qij else { continue };
            if i == j {
                mean += qij;
            }
            second += qij * qij.transpose() * 2.0;
        }
    }
    second += &mean * mean.transpose();
    out.view_mut((0, 0), (n, n)).copy_from(&second);
    out
}

/// `x̂` moved along `g` (its held parameters first, then the estimated
/// ones) and settled along every combination H-orthogonal to the long
/// directions (the constraints `Kᵀ y = 0` on each step `y`, `K`'s columns
/// `H d_k`), less the generator's own first-order change: the
/// second-order offset from `x̂` in the estimated parameters' coordinates.
/// `None` where a step does not give a model.
fn settle(
    problem: &Problem<'_>,
    held: &[Param],
    at: &State,
    g: &Generator,
    keep: &DMatrix<f64>,
) -> Option<DVector<f64>> {
    let from = held
        .iter()
        .zip(g.held.iter())
        .fold(at.clone(), |s, (p, d)| s.perturbed(*p, *d));
    let mut x = problem.moved(&from, &g.est).ok()?;
    for _ in 0..SETTLE_STEPS {
        let normal = problem.evaluate(&x);
        if !normal.cost().is_finite() {
            return None;
        }
        // min ½ yᵀA y − gᵀy subject to Kᵀy = 0: y = A⁻¹(g − K μ),
        // μ = (KᵀA⁻¹K)⁻¹ KᵀA⁻¹g.
        let chol = normal.jtj().clone().cholesky()?;
        let ag = chol.solve(normal.jtr());
        let y = if keep.ncols() == 0 {
            ag
        } else {
            let ak = chol.solve(keep);
            let mu = (keep.transpose() * &ak)
                .cholesky()?
                .solve(&(keep.transpose() * &ag));
            ag - ak * mu
        };
        x = problem.moved(&x, &y).ok()?;
    }
    Some(DVector::from_vec(difference(at, &x, problem.params)) - &g.est)
}
