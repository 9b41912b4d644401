//! The hold rule of the adjustment ([`super::adjust`]): which candidate
//! parameters the data determine better than their prior ranges, judged
//! with the same priors the adjustment's cost carries, and the condition
//! numbers the report keeps.

use nalgebra::DMatrix;
use serde::Serialize;

use super::params::Param;

/// A parameter held at its nominal value, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Held {
    /// Its name.
    pub name: String,
    /// Its marginal σ from the data and its prior range together (at most
    /// the prior range; near it: the data add nothing).
    pub marginal_std: f64,
    /// Its prior range, the σ it is held with.
    pub prior_std: f64,
    /// Condition number of the scaled normal matrix before holding it.
    pub condition_before: f64,
}

/// What one adjustment estimated and held.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Selection {
    /// Estimated parameters, by name.
    pub estimated: Vec<String>,
    /// Held parameters.
    pub held: Vec<Held>,
    /// Condition number of the scaled normal matrix over every candidate.
    pub condition_all: f64,
    /// Condition number over the estimated ones.
    pub condition_estimated: f64,
}

/// Condition number of a normal matrix in its correlation-scaled form
/// (infinite where a parameter has no column at all).
fn condition(n: &DMatrix<f64>) -> f64 {
    let dim = n.nrows();
    let d: Vec<f64> = (0..dim).map(|i| n[(i, i)].max(0.0).sqrt()).collect();
    if d.contains(&0.0) {
        return f64::INFINITY;
    }
    let c = DMatrix::from_fn(dim, dim, |i, j| n[(i, j)] / (d[i] * d[j]));
    let eig = c.symmetric_eigenvalues();
    let (max, min) = (eig.max(), eig.min());
    if min > 0.0 {
        max / min
    } else {
        f64::INFINITY
    }
}

/// Each parameter's marginal σ once its prior range is added to the data
/// (`N + diag(1/prior²)`, the plane's parameters without prior): finite
/// even along a degeneracy, where the parameter's σ is its prior's and its
/// partners' follow from it. `None` when even so the matrix is singular.
fn posterior_std(n: &DMatrix<f64>, priors: &[Option<f64>]) -> Option<Vec<f64>> {
    let dim = n.nrows();
    let mut m = n.clone();
    for (i, p) in priors.iter().enumerate() {
        if let Some(p) = p {
            m[(i, i)] += 1.0 / (p * p);
        }
    }
    let d: Vec<f64> = (0..dim)
        .map(|i| m[(i, i)].max(f64::MIN_POSITIVE).sqrt())
        .collect();
    let c = DMatrix::from_fn(dim, dim, |i, j| m[(i, j)] / (d[i] * d[j]));
    let inv = c.cholesky()?.inverse();
    Some((0..dim).map(|i| inv[(i, i)].sqrt() / d[i]).collect())
}

pub(super) fn submatrix(n: &DMatrix<f64>, rows: &[usize], cols: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), cols.len(), |i, j| n[(rows[i], cols[j])])
}

/// A parameter is held when, with its prior range added, the data leave
/// its σ above `1/√2` of that range: the data alone know it no better than
/// the prior does (`1/σ² = 1/σ_data² + 1/prior²`).
const HOLD_RATIO: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// Holds, one at a time and worst first, each parameter that the data do
/// not determine better than its prior range ([`HOLD_RATIO`]).
pub fn select(n: &DMatrix<f64>, params: &[Param]) -> (Vec<usize>, Selection) {
    let mut active: Vec<usize> = (0..params.len()).collect();
    let mut held = Vec::new();
    let condition_all = condition(n);
    loop {
        let sub = submatrix(n, &active, &active);
        let cond = condition(&sub);
        let priors: Vec<Option<f64>> = active.iter().map(|&i| params[i].prior_std()).collect();
        let sigma =
            posterior_std(&sub, &priors).unwrap_or_else(|| vec![f64::INFINITY; active.len()]);
        let worst = active
            .iter()
            .enumerate()
            .filter_map(|(k, _)| priors[k].map(|p| (k, sigma[k], p)))
            .max_by(|a, b| (a.1 / a.2).total_cmp(&(b.1 / b.2)));
        match worst {
            Some((k, s, p)) if s > HOLD_RATIO * p => {
                let i = active.remove(k);
                // Debug, not info: the report's summary says what each step
                // held and why, once; `select` runs more than once a step.
                log::debug!(
                    "calibration: holding {} (σ {s:.3e} against prior {p:.3e})",
                    params[i].name()
                );
                held.push(Held {
                    name: params[i].name().to_string(),
                    marginal_std: s,
                    prior_std: p,
                    condition_before: cond,
                });
            }
            _ => {
                let selection = Selection {
                    estimated: active
                        .iter()
                        .map(|&i| params[i].name().to_string())
                        .collect(),
                    held,
                    condition_all,
                    condition_estimated: cond,
                };
                return (active, selection);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::station::Dof;

    #[test]
    fn a_degenerate_pair_holds_the_one_with_the_narrow_prior() {
        // Two parameters seen only through their sum (a pitch and a distance
        // that scale together): the one whose prior is narrow is held, the
        // other is then determined through it.
        let j = DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 0.0, 2.0, 2.0, 0.0, 0.0, 0.0, 1.0]);
        let n = j.transpose() * &j;
        let params = [
            Param::Station(Dof::ScreenZ),
            Param::Station(Dof::ScreenPitch),
            Param::Station(Dof::CameraX),
        ];
        let (keep, sel) = select(&n, &params);
        assert_eq!(keep, vec![0, 2]);
        assert_eq!(sel.held.len(), 1);
        assert_eq!(sel.held[0].name, "screen.pixel_pitch_mm");
        assert!(sel.condition_all.is_infinite() || sel.condition_all > 1e12);
        assert!(sel.condition_estimated < 10.0);
    }
}
