//! The surface-domain estimator: both surfaces fitted to the frames
//! directly, so that plates whose two reflections cannot be told apart
//! pixel by pixel (1–5 mm) are measured, and no per-pixel estimator's bias
//! at sub-bin separation reaches the surfaces.
//!
//! The unknowns are what the scene has: the Zernike coefficients of front
//! and back, and per pixel the nuisance of the spectral model (background,
//! amplitudes, κ). Every iteration evaluates each pixel's exact likelihood
//! (its series or sufficient statistics, through [`Samples`]) at the screen
//! points the current surfaces predict, profiles the nuisance out in closed
//! form ([`pixel`]), and hands the resulting Gaussian pseudo-observations
//! to the surface solver ([`crate::solve::surfaces::reconstruct`]): the
//! surface solver's least squares on them is the Gauss–Newton step of the
//! global likelihood in the coefficients, through the exact forward model.
//! A step that does not lower the global objective `Σ N_p ln RSS_p` (the
//! likelihood with each pixel's noise profiled out) is halved. At the fixed
//! point the covariance the surface solver reports is the inverse of the
//! global Fisher information: an honest σ per coefficient, from the
//! information all pixels share rather than what each pixel alone resolves.
//! The number of terms is the surface solver's information criterion on
//! the pseudo-observations, i.e. on the quadratic model of the global
//! likelihood.
//!
//! Not modelled: a third reflection (the per-pixel stage's
//! `--third-reflection` scenes are fitted with two); rim pixels whose back
//! offset the spectral stage had to borrow (the flat plate's back path
//! leaves through the edge there) are left out.

pub mod pixel;
mod report;
pub mod run;
mod separation;

pub use report::DirectReport;
pub use run::{
    solve, Clipped, DirectError, DirectOptions, DirectSolution, Iteration, Starts, ThirdReflection,
};
pub use separation::{
    median_separation_bins, median_separation_bins_of, surface_domain_preferred, DIRECT_BELOW_BINS,
};
