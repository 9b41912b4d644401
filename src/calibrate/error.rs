//! What can stop a calibration's adjustment, each naming the session entry
//! or step at fault and what to do.

use std::path::PathBuf;

/// Why a calibration could not be computed or written.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// Too few readings of one kind.
    #[error("session: {found} `{entry}` entries, at least {needed} needed: take more readings")]
    TooFew {
        /// The session entry (`flat_point`, `target_point`, ...).
        entry: &'static str,
        /// How many there are.
        found: usize,
        /// How many the step needs.
        needed: usize,
    },
    /// The readings of one kind do not span what the step needs.
    #[error("session: the `{entry}` entries {problem}")]
    Degenerate {
        /// The session entry.
        entry: &'static str,
        /// What is wrong and what to do.
        problem: String,
    },
    /// A covariance given with an entry is not positive definite.
    #[error("session: `{entry}` {index}: its covariance is not positive definite: check its noise figures")]
    BadCovariance {
        /// The session entry.
        entry: &'static str,
        /// Its index in the session.
        index: usize,
    },
    /// A least-squares step did not converge.
    #[error("calibration step `{step}` did not converge after {trials} trials ({stop}){detail}")]
    NotConverged {
        /// The step (`resection`, `screen`, `joint`).
        step: &'static str,
        /// Trial steps evaluated.
        trials: usize,
        /// Why it stopped.
        stop: String,
        /// What moved and which readings fit worst (empty, or `; …`).
        detail: String,
    },
    /// The calibrated station is not a valid station (e.g. a distortion
    /// whose inverse is not unique over the sensor).
    #[error(
        "the calibrated station is not valid: {source}; check the targets' spread over the sensor"
    )]
    InvalidResult {
        /// The station's own error, naming the field.
        #[source]
        source: crate::optics::station::StationError,
    },
    /// Writing the result failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

impl crate::outcome::Classify for CalibrationError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            // The session's readings: too few, degenerate, or with a
            // covariance that is not one, or a result the readings make
            // invalid (the targets' spread): fix the session.
            CalibrationError::TooFew { .. }
            | CalibrationError::Degenerate { .. }
            | CalibrationError::BadCovariance { .. }
            | CalibrationError::InvalidResult { .. } => Some(Outcome::Input),
            // No convergence: no class of its own (exit 1).
            CalibrationError::NotConverged { .. } => None,
            CalibrationError::Io { source, .. } => crate::outcome::io_outcome(source),
        }
    }
}
