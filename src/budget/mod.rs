//! The error budget of a measurement (paper §5.1, Tables 1–4, made from the
//! exact model): how every degree of freedom of the station
//! (`mfd-station-uncertainty/1`, `interchange.md`) moves every Zernike
//! coefficient of front and back, times its uncertainty, beside the imaging
//! noise; the total; and which degrees of freedom the element's own data pin
//! down better than their prior.
//!
//! Conventions, fixed here for every part of the budget:
//! - A *sensitivity* is the change of a reconstructed coefficient (nm) per
//!   unit (the unit of the degree of freedom's spec name) by which the
//!   station the reconstruction assumes exceeds the true one, the measured
//!   screen points held fixed. Frames taken on the true station and
//!   reconstructed with a station wrong by `δ` in one degree of freedom
//!   change the coefficients by `sensitivity · δ` to first order.
//! - Coefficients are in Noll order from j = 1, RMS normalisation, index
//!   `k` for `j = k + 1`, as in `surfaces.json`.
//! - RMS figures over the aperture leave piston and tilt out (j ≥ 4), as
//!   `expected_error_rms_nm` of `mfd-surfaces/2` does.

pub mod assemble;
pub mod fisher;
pub mod linear;
pub mod monte_carlo;
pub mod picture;
pub mod refine;
pub mod scene;
pub mod station_dual;
pub mod table;

use nalgebra::DMatrix;

use crate::optics::station::Dof;

/// One degree of freedom's row of the budget.
#[derive(Debug, Clone, PartialEq)]
pub struct DofEntry {
    /// The degree of freedom.
    pub dof: Dof,
    /// Its 1σ, in its unit (from the uncertainty file or the command line).
    pub std: f64,
    /// Front coefficients' change per unit, nm per unit, Noll order from j = 1.
    pub front_nm_per_unit: Vec<f64>,
    /// The same for the back; empty when the back was not reconstructed.
    pub back_nm_per_unit: Vec<f64>,
}

impl DofEntry {
    /// The front's change at one σ, nm per coefficient.
    pub fn front_contribution_nm(&self) -> Vec<f64> {
        self.front_nm_per_unit
            .iter()
            .map(|s| s * self.std)
            .collect()
    }

    /// The back's change at one σ, nm per coefficient.
    pub fn back_contribution_nm(&self) -> Vec<f64> {
        self.back_nm_per_unit.iter().map(|s| s * self.std).collect()
    }
}

/// A contribution that is not a degree of freedom of the station (imaging
/// noise, the multiple reflection, the reference flat's figure): its 1σ (or
/// bias) per coefficient.
#[derive(Debug, Clone, PartialEq)]
pub struct OtherEntry {
    /// What it is, in words an operator reads ("imaging noise", ...).
    pub name: String,
    /// Whether it is a bias (a fixed, signed change) rather than a 1σ.
    pub bias: bool,
    /// Per front coefficient, nm (σ, or the signed bias).
    pub front_nm: Vec<f64>,
    /// Per back coefficient, nm; empty when the back was not reconstructed.
    pub back_nm: Vec<f64>,
}

/// How well the element's own data determine one degree of freedom, or one
/// combination of them, the surfaces estimated at the same time.
#[derive(Debug, Clone, PartialEq)]
pub struct Identifiability {
    /// The combination, unit-σ scaled: `(dof, weight)` with the weights a
    /// unit vector in the space of `δθ_i / σ_i`. A single degree of freedom
    /// has one entry of weight 1.
    pub combination: Vec<(Dof, f64)>,
    /// Its 1σ from the prior (the uncertainty file), in σ units (1 for a
    /// single degree of freedom).
    pub prior_std: f64,
    /// Its 1σ from the data alone (inverse Fisher information with the
    /// surfaces marginalised), in the same units; `None` where the data do
    /// not determine it at all (degenerate).
    pub data_std: Option<f64>,
    /// Its 1σ from prior and data together.
    pub posterior_std: f64,
}

/// The whole budget of one station, schedule or acquisition, and expected
/// surfaces.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// Terms per surface in every vector below (front, back).
    pub terms: [usize; 2],
    /// Whether the back was reconstructed (some back reflection measured).
    pub back_fitted: bool,
    /// The station's degrees of freedom with a σ > 0, in the uncertainty
    /// file's order.
    pub dofs: Vec<DofEntry>,
    /// Their correlation (covariance scaled to unit σ), `dofs.len()` square.
    pub correlation: DMatrix<f64>,
    /// Everything else: imaging noise first, then any others.
    pub others: Vec<OtherEntry>,
    /// Covariance of the front coefficients from every σ above (the
    /// degrees of freedom with their correlation, and the others that are
    /// not biases), nm². Biases add to the table's root sum of squares.
    pub front_total_cov_nm2: DMatrix<f64>,
    /// The same for the back (0 × 0 when not reconstructed).
    pub back_total_cov_nm2: DMatrix<f64>,
    /// What the data pin down: every single degree of freedom, then the
    /// combinations the data determine worst (degenerate ones included).
    pub identifiability: Vec<Identifiability>,
}
