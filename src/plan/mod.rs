//! Measurement planning (`mfd plan`): predicted accuracy and time of a schedule before the first frame, and schedules designed for a frame budget, a time budget or a target accuracy.
//!
//! - [`predict`]: one schedule on one station → [`Prediction`]: the
//!   Cramér–Rao bound of both surfaces per Zernike term and as RMS, whether
//!   the two reflections are separable and the fit's start unambiguous, and
//!   the acquisition time. The bound is the per-pixel one (the spectral
//!   stage's bound at the traced flat plate, propagated through the surface
//!   solver's normal equations, as `mfd budget` does) where the reflections
//!   are far enough apart for `--estimator auto` to take the per-pixel
//!   route, and the surface-domain fit's global bound where they are not
//!   ([`BoundKind`]); measurable means the spectral stage finds the true
//!   points (per-pixel) or the surface-domain fit converges from the flat
//!   plate ([`converge`]).
//! - [`design`]: the schedule for a budget of frames, seconds or a target
//!   error ([`design::design`]).
//! - [`timing`]: seconds of an acquisition at the display's settle time and
//!   the camera's frame period.

pub mod ambiguity;
pub mod converge;
pub mod design;
pub mod predict;
pub mod stage;
pub mod timing;

use std::path::PathBuf;

pub use converge::Convergence;
pub use design::{design, Budget, DesignOptions, Designed};
pub use predict::{predict, BoundKind, Prediction, Separation, SurfacePrediction};
pub use stage::StageCheck;
pub use timing::Timing;

use crate::budget::scene::Radiometry;

/// What went wrong planning.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// An option or input is out of range.
    #[error("{input}: {problem}")]
    Invalid {
        /// The option or field, e.g. `--tau-max` or `the schedule`.
        input: String,
        /// What is wrong and what to do.
        problem: String,
    },
    /// The scene (trace, bound, reconstruction) could not be made.
    #[error(transparent)]
    Budget(#[from] crate::budget::scene::BudgetError),
    /// The surface solver could not propagate the bound.
    #[error("propagating the bound to the surfaces: {0}")]
    Surface(#[from] crate::solve::surfaces::SurfaceError),
    /// The display profile could not be read.
    #[error(transparent)]
    Station(#[from] crate::optics::station::StationError),
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

impl crate::outcome::Classify for PlanError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            // An option's value (`input` names it: `--frames`) the plan
            // cannot take is a bad command line; the schedule's or the
            // design's own troubles are input that is not valid.
            PlanError::Invalid { input, .. } if input.starts_with("--") => Some(Outcome::Range),
            PlanError::Invalid { .. } => Some(Outcome::Input),
            PlanError::Budget(e) => e.outcome(),
            PlanError::Surface(e) => e.outcome(),
            PlanError::Station(e) => e.outcome(),
            PlanError::Io { source, .. } => crate::outcome::io_outcome(source),
        }
    }
}

pub(crate) fn invalid(input: impl Into<String>, problem: impl Into<String>) -> PlanError {
    PlanError::Invalid {
        input: input.into(),
        problem: problem.into(),
    }
}

/// The scene a plan is made for, besides the station and schedule.
#[derive(Debug, Clone)]
pub struct PlanOptions {
    /// The camera's radiometry: noise, bit depth, ambient light, τ_max.
    pub radiometry: Radiometry,
    /// Zernike terms per surface.
    pub terms: usize,
    /// Factor on the back reflection's Fresnel weight: 0 for an AR-coated
    /// back (one reflection, nothing to separate).
    pub back_scale: f64,
    /// Expected size of either surface's departure from flat, nm RMS: how
    /// far the true screen points may lie from the nominal-plate prediction.
    pub surface_nm: f64,
    /// The station's own share of the prior's spread (calibration, the
    /// element's placement), screen px.
    pub station_spread_px: f64,
    /// The acquisition's timing.
    pub timing: Timing,
    /// Block size of the bound's evaluation; `None`: automatic.
    pub bound_stride_px: Option<usize>,
    /// The spectral stage's settings the schedule will be reconstructed
    /// with (engine, band, iteration cap): the stage run on sample pixels
    /// ([`stage`]) uses them.
    pub spectral: crate::solve::spectral::SpectralConfig,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            radiometry: Radiometry::default(),
            terms: 36,
            back_scale: 1.0,
            surface_nm: 200.0,
            station_spread_px: 3.0,
            timing: Timing::default(),
            bound_stride_px: None,
            spectral: crate::solve::spectral::SpectralConfig::default(),
        }
    }
}

impl PlanOptions {
    /// Checks the ranges, each error naming its option.
    ///
    /// # Errors
    /// [`PlanError::Invalid`] naming the option.
    pub fn validate(&self) -> Result<(), PlanError> {
        let r = &self.radiometry;
        if !(r.noise_frac.is_finite() && r.noise_frac > 0.0 && r.noise_frac < 1.0) {
            return Err(invalid(
                "--noise",
                format!(
                    "expected a fraction of full scale in (0, 1) (a bound needs noise), found {}",
                    r.noise_frac
                ),
            ));
        }
        if !(r.tau_max.is_finite() && r.tau_max > 0.0) {
            return Err(invalid(
                "--tau-max",
                format!("expected τ_max > 0, found {}", r.tau_max),
            ));
        }
        if self.terms < 4 {
            return Err(invalid(
                "--terms",
                format!("expected at least 4, found {}", self.terms),
            ));
        }
        if !(self.back_scale.is_finite() && self.back_scale >= 0.0) {
            return Err(invalid(
                "--back-scale",
                format!("expected a factor ≥ 0, found {}", self.back_scale),
            ));
        }
        for (name, v) in [
            ("--surface-nm", self.surface_nm),
            ("--station-spread-px", self.station_spread_px),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(name, format!("expected a value ≥ 0, found {v}")));
            }
        }
        self.timing.validate()
    }
}
