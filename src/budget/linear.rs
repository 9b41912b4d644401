//! The budget of one solution: the sensitivities of its coefficients to the
//! station's degrees of freedom, the noise covariance, the total.
//!
//! This version takes each degree of freedom's sensitivity from a re-solve
//! of the same observations on the station changed by one σ
//! ([`station_induced`]), divided by that σ.

use nalgebra::DMatrix;

use super::{Budget, DofEntry, OtherEntry};
use crate::optics::station::{Station, StationUncertainty};
use crate::solve::surfaces::station_error::station_induced_columns;
use crate::solve::surfaces::{Observations, SurfaceError, SurfaceOptions, SurfaceSolution};

/// The name of the imaging-noise entry of [`Budget::others`].
pub const IMAGING_NOISE: &str = "imaging noise";

/// The budget of `solution` (solved from `obs` on `station`) under the
/// station's `uncertainty`.
///
/// # Errors
/// [`SurfaceError`] when a changed station's solve fails.
pub fn budget(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    solution: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<Budget, SurfaceError> {
    let cols = station_induced_columns(obs, station, uncertainty, solution, opts)?;
    let nf = solution.front.coefficients_nm().len();
    let nb = if solution.back_fitted {
        solution.back.coefficients_nm().len()
    } else {
        0
    };
    let mut dofs = Vec::new();
    let mut keep = Vec::new();
    for (k, col) in cols.iter().enumerate() {
        let Some((front, back)) = col else { continue };
        let std = uncertainty.covariance[(k, k)].sqrt();
        keep.push(k);
        dofs.push(DofEntry {
            dof: uncertainty.names[k],
            std,
            front_nm_per_unit: front.iter().map(|x| x / std).collect(),
            back_nm_per_unit: back.iter().take(nb).map(|x| x / std).collect(),
        });
    }
    let correlation = DMatrix::from_fn(keep.len(), keep.len(), |r, c| {
        let (a, b) = (keep[r], keep[c]);
        uncertainty.covariance[(a, b)] / (dofs[r].std * dofs[c].std)
    });
    let (noise_f, noise_b) = noise_covariances(solution, nf, nb);
    let noise = OtherEntry {
        name: IMAGING_NOISE.into(),
        bias: false,
        front_nm: (0..nf).map(|i| noise_f[(i, i)].max(0.0).sqrt()).collect(),
        back_nm: (0..nb).map(|i| noise_b[(i, i)].max(0.0).sqrt()).collect(),
    };
    let front_total_cov_nm2 =
        station_covariance(&dofs, &correlation, nf, |d| &d.front_nm_per_unit) + noise_f;
    let back_total_cov_nm2 =
        station_covariance(&dofs, &correlation, nb, |d| &d.back_nm_per_unit) + noise_b;
    Ok(Budget {
        terms: [nf, nb],
        back_fitted: solution.back_fitted,
        dofs,
        correlation,
        others: vec![noise],
        front_total_cov_nm2,
        back_total_cov_nm2,
        identifiability: Vec::new(),
    })
}

/// `S Σ Sᵀ` with `S` the per-σ contributions (n × m) and `Σ` the correlation.
pub fn station_covariance(
    dofs: &[DofEntry],
    correlation: &DMatrix<f64>,
    n: usize,
    per_unit: impl Fn(&DofEntry) -> &Vec<f64>,
) -> DMatrix<f64> {
    let s = DMatrix::from_fn(n, dofs.len(), |i, k| {
        per_unit(&dofs[k]).get(i).copied().unwrap_or(0.0) * dofs[k].std
    });
    &s * correlation * s.transpose()
}

/// The solution's noise covariance split into front (`nf` square) and back
/// (`nb` square) in coefficient order, zero rows for fixed coefficients.
pub fn noise_covariances(
    solution: &SurfaceSolution,
    nf: usize,
    nb: usize,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let layout = &solution.layout;
    let c = &solution.covariance;
    let pick = |n: usize, col: &dyn Fn(usize) -> Option<usize>| {
        DMatrix::from_fn(n, n, |i, j| match (col(i), col(j)) {
            (Some(a), Some(b)) if a < c.nrows() && b < c.ncols() => c[(a, b)],
            _ => 0.0,
        })
    };
    (
        pick(nf, &|k| layout.front_col(k)),
        pick(nb, &|k| layout.back_col(k)),
    )
}
