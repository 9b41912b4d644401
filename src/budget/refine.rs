//! Degrees of freedom the data pin down, measured rather than assumed: the
//! chosen ones estimated jointly with the surfaces, the uncertainty file's
//! covariance as their prior (`mfd reconstruct --refine
//! element.thickness_mm,...`).
//!
//! Gauss–Newton on the reduced problem: at the current station the surfaces
//! are solved (terms fixed), the fit is linearised ([`linearise`]) and the
//! coefficients eliminated ([`marginal_information`]), leaving for the
//! offsets `θ` of the chosen degrees of freedom from the assumed station
//!
//! `(F + P⁻¹) δ = −(g / scale + P⁻¹ θ)`,
//!
//! `F` the data's information, `g` the reduced gradient, `P` the prior's
//! covariance of those degrees of freedom. The station moves by `δ`, and the
//! loop ends when every `|δ_i|` is below [`STEP_TOL_SIGMA`] of its prior σ.
//! `(F + P⁻¹)⁻¹` at the end is the estimates' covariance.

use nalgebra::{DMatrix, DVector};

use super::fisher::marginal_information;
use super::linear::linearise;
use crate::optics::station::{Dof, Station, StationUncertainty};
use crate::solve::surfaces::station_error::with_station;
use crate::solve::surfaces::{
    reconstruct, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
};

/// The loop ends when no degree of freedom moves by more than this
/// fraction of its prior σ: 1e-3 σ changes any reported σ by < 1e-6.
pub const STEP_TOL_SIGMA: f64 = 1e-3;

/// Gauss–Newton iterations at most; the problem is nearly linear over a
/// prior σ, so 2–4 suffice.
pub const MAX_ITER: usize = 10;

/// One refined degree of freedom.
#[derive(Debug, Clone, PartialEq)]
pub struct RefinedDof {
    /// The degree of freedom.
    pub dof: Dof,
    /// The estimate's change from the assumed station, in its unit.
    pub change: f64,
    /// Its prior 1σ (the uncertainty file's).
    pub prior_std: f64,
    /// Its 1σ after the data (prior and data together).
    pub posterior_std: f64,
}

/// The refined station and the surfaces solved on it.
#[derive(Debug, Clone)]
pub struct Refined {
    /// The assumed station moved to the estimates.
    pub station: Station,
    /// The estimates, in the order asked for.
    pub estimates: Vec<RefinedDof>,
    /// Their covariance (posterior), in their units.
    pub covariance: DMatrix<f64>,
    /// The uncertainty with the refined degrees of freedom's rows replaced
    /// by the posterior (their correlation with the others dropped: the
    /// data, not the prior, now set them).
    pub uncertainty: StationUncertainty,
    /// The surfaces on the refined station.
    pub solution: SurfaceSolution,
    /// Gauss–Newton iterations run.
    pub iterations: usize,
    /// Whether the last step was below [`STEP_TOL_SIGMA`].
    pub converged: bool,
}

/// Errors of a refinement.
#[derive(Debug, thiserror::Error)]
pub enum RefineError {
    /// A degree of freedom asked for has no σ in the uncertainty file.
    #[error(
        "--refine {dof}: the station uncertainty gives it no σ; a refined \
         degree of freedom needs a prior (add it to the uncertainty file)"
    )]
    NoPrior {
        /// The spec name.
        dof: &'static str,
    },
    /// The surfaces could not be solved or linearised.
    #[error(transparent)]
    Surface(#[from] SurfaceError),
}

impl crate::outcome::Classify for RefineError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            RefineError::NoPrior { .. } => Some(Outcome::Input),
            RefineError::Surface(e) => e.outcome(),
        }
    }
}

/// Estimates `dofs` jointly with the surfaces of `obs` (built on `station`),
/// with the prior of `uncertainty`; `opts` with the terms fixed.
///
/// # Errors
/// [`RefineError::NoPrior`] for a degree of freedom without a σ;
/// [`RefineError::Surface`] when a solve fails.
pub fn refine(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    dofs: &[Dof],
    opts: &SurfaceOptions,
) -> Result<Refined, RefineError> {
    let index: Vec<usize> = dofs
        .iter()
        .map(|&d| {
            uncertainty
                .names
                .iter()
                .position(|&n| n == d)
                .filter(|&k| uncertainty.covariance[(k, k)] > 0.0)
                .ok_or(RefineError::NoPrior { dof: d.name() })
        })
        .collect::<Result<_, _>>()?;
    let m = dofs.len();
    let prior = DMatrix::from_fn(m, m, |r, c| uncertainty.covariance[(index[r], index[c])]);
    let prior_inv = prior
        .clone()
        .cholesky()
        .ok_or(SurfaceError::IllConditioned {
            stage: "refine: prior",
            condition_number: f64::INFINITY,
        })?
        .inverse();
    let sigma: Vec<f64> = (0..m).map(|k| prior[(k, k)].sqrt()).collect();
    let mut theta = DVector::<f64>::zeros(m);
    let mut current = station.clone();
    let mut iterations = 0;
    let mut converged = false;
    let mut posterior = prior.clone();
    let mut solution;
    loop {
        let here = with_station(obs, &current);
        solution = reconstruct(&here, &current, opts)?;
        if converged || iterations == MAX_ITER {
            break;
        }
        let lin = linearise(&here, &current, &solution, opts)?;
        let (f, _) = marginal_information(&lin, dofs);
        let g = DVector::from_fn(m, |r, _| lin.reduced_gradient[dofs[r] as usize]);
        let h = &f + &prior_inv;
        let chol = h.cholesky().ok_or(SurfaceError::IllConditioned {
            stage: "refine",
            condition_number: f64::INFINITY,
        })?;
        let step = -chol.solve(&(g / lin.covariance_scale + &prior_inv * &theta));
        posterior = chol.inverse();
        theta += &step;
        for (k, &d) in dofs.iter().enumerate() {
            current = current.perturbed(d, step[k]);
        }
        iterations += 1;
        converged = (0..m).all(|k| step[k].abs() < STEP_TOL_SIGMA * sigma[k]);
    }
    let estimates = (0..m)
        .map(|k| RefinedDof {
            dof: dofs[k],
            change: theta[k],
            prior_std: sigma[k],
            posterior_std: posterior[(k, k)].sqrt(),
        })
        .collect();
    let mut refined = uncertainty.clone();
    for (r, &a) in index.iter().enumerate() {
        for k in 0..refined.names.len() {
            refined.covariance[(a, k)] = 0.0;
            refined.covariance[(k, a)] = 0.0;
        }
        for (c, &b) in index.iter().enumerate() {
            refined.covariance[(a, b)] = posterior[(r, c)];
        }
    }
    Ok(Refined {
        station: current,
        estimates,
        covariance: posterior,
        uncertainty: refined,
        solution,
        iterations,
        converged,
    })
}
