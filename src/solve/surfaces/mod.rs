//! Surface solvers: the element's front and back surfaces as Zernike
//! expansions from the screen points S1 and S2 of every camera pixel.
//!
//! Stages (paper §2.3–2.4, made exact): the front from the S1 slopes by the
//! vector law of reflection with iterative correction of the reflection
//! points ([`front`]); the back by inverse ray tracing through that front and
//! Levenberg–Marquardt over the back coefficients ([`lm`], with the analytic
//! Jacobian of [`path`]); then both jointly on S1 and S2 weighted by the
//! spectral solver's σ, with the coefficient covariance; the number of
//! terms chosen by the Bayesian information criterion ([`select`]).

pub mod convergence;
pub mod dual;
pub mod front;
pub mod lm;
pub mod observe;
mod outliers;
pub mod path;
pub mod problem;
pub mod report;
pub mod select;
pub mod solve;
pub mod station_error;

pub use problem::{Layout, Observation, Observations, Uncertainty};
pub use solve::{reconstruct, SurfaceOptions, SurfaceSolution};

use crate::optics::zernike::ZernikeError;

/// Errors of the surface solvers.
#[derive(Debug, thiserror::Error)]
pub enum SurfaceError {
    /// An input array does not fit the station.
    #[error("{what}: {problem}")]
    Input {
        /// The input (file or array) at fault.
        what: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// Too few measured points for the unknowns.
    #[error("{stage}: {have} measured values for {need} unknowns")]
    TooFewPoints {
        /// The stage.
        stage: &'static str,
        /// Residual components available.
        have: usize,
        /// Unknowns.
        need: usize,
    },
    /// The normal equations are singular to working precision.
    #[error(
        "{stage}: ill-conditioned (condition number {condition_number:.3e}); \
         fewer terms or more coverage needed"
    )]
    IllConditioned {
        /// The stage.
        stage: &'static str,
        /// Condition number of the weighted Jacobian.
        condition_number: f64,
    },
    /// A Zernike basis or fit failed.
    #[error(transparent)]
    Zernike(#[from] ZernikeError),
}

impl crate::outcome::Classify for SurfaceError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            SurfaceError::TooFewPoints { .. } => Some(Outcome::NoSignal),
            SurfaceError::Input { .. } => Some(Outcome::Input),
            SurfaceError::Zernike(e) => e.outcome(),
            SurfaceError::IllConditioned { .. } => None,
        }
    }
}
