//! The budget of one solution, assembled: each degree of freedom's
//! sensitivity from the reconstruction's linearisation
//! ([`super::linear`]), the imaging noise from the solution's covariance,
//! their total, and what the data pin down ([`super::fisher`]).

use nalgebra::DMatrix;

use super::fisher::identifiability;
use super::linear::{linearise, noise_covariances, station_covariance};
use super::{Budget, DofEntry, OtherEntry};
use crate::optics::station::{Station, StationUncertainty};
use crate::solve::surfaces::{Observations, SurfaceError, SurfaceOptions, SurfaceSolution};

/// The name of the imaging-noise entry of [`Budget::others`].
pub const IMAGING_NOISE: &str = "imaging noise";

/// The budget of `solution` (solved from `obs` on `station`) under the
/// station's `uncertainty`: each degree of freedom's sensitivity from the
/// linearisation ([`linearise`]), the noise, the total, and what the data
/// pin down ([`super::fisher`]).
///
/// # Errors
/// [`SurfaceError::IllConditioned`] when the normal equations at the
/// solution are not positive definite.
pub fn budget(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    solution: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<Budget, SurfaceError> {
    let lin = linearise(obs, station, solution, opts)?;
    let per_unit = lin.sensitivity()?;
    let mut dofs: Vec<DofEntry> = Vec::new();
    let mut keep = Vec::new();
    for (k, &dof) in uncertainty.names.iter().enumerate() {
        let std = uncertainty.covariance[(k, k)].sqrt();
        if std > 0.0 {
            let (front, back) = lin.coefficients(&per_unit, dof as usize, solution);
            keep.push(k);
            dofs.push(DofEntry {
                dof,
                std,
                front_nm_per_unit: front,
                back_nm_per_unit: back,
            });
        }
    }
    let nf = solution.front.coefficients_nm().len();
    let nb = if solution.back_fitted {
        solution.back.coefficients_nm().len()
    } else {
        0
    };
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
        identifiability: identifiability(&lin, uncertainty)?,
    })
}
