//! The pipeline's error: which stage or file failed, with its cause, and
//! the class of failure each variant is (bad input where a file or value is
//! at fault; the cause decides otherwise).

use std::path::PathBuf;

use crate::acquire::acquisition::AcquisitionError;
use crate::formats::npy::NpyError;
use crate::formats::surfaces_file::SurfacesFileError;
use crate::optics::station::UncertaintyError;
use crate::plot::PlotError;
use crate::solve::spectral::SpectralError;

/// Errors of the pipeline: which stage or file failed, with its cause.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Reading the acquisition failed.
    #[error(transparent)]
    Acquisition(#[from] AcquisitionError),
    /// The spectral stage failed.
    #[error(transparent)]
    Spectral(#[from] SpectralError),
    /// An NPY array could not be read or written.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// An array does not fit the station.
    #[error("{path}: shape {found:?}, expected {expected:?} ({what}) for the station's camera")]
    Shape {
        /// The file.
        path: PathBuf,
        /// Its shape.
        found: Vec<usize>,
        /// The shape the station implies.
        expected: Vec<usize>,
        /// What the axes are.
        what: &'static str,
    },
    /// `surfaces.json` could not be written.
    #[error(transparent)]
    SurfacesFile(#[from] SurfacesFileError),
    /// A picture could not be drawn or written.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// A file or folder of the result could not be written.
    #[error("writing {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A result folder cannot be used (a file, or a folder that is not
    /// an mfd result).
    #[error("{path}: {problem}")]
    Output {
        /// The folder.
        path: PathBuf,
        /// Why.
        problem: String,
    },
    /// The data hold nothing the stages can measure: which pixels were
    /// looked at and what was found, in words.
    #[error("{0}")]
    NoSignal(String),
    /// The frames show the back reflection of a wedge the station does
    /// not declare, and not clearly enough to measure from: the wedge seen
    /// and the station fields to set, in words.
    #[error("{0}")]
    UndeclaredWedge(String),
    /// A station uncertainty file could not be read.
    #[error(transparent)]
    Uncertainty(#[from] UncertaintyError),
    /// The refined station could not be written.
    #[error(transparent)]
    Station(#[from] crate::optics::station::StationError),
    /// A station uncertainty file is that of another station.
    #[error(
        "{uncertainty}: its `station` field names \"{named}\" ({resolved}), but the station \
         used is {station}, a different station: give the uncertainty of this station \
         (--uncertainty), or the station it belongs to (--station)"
    )]
    UncertaintyOfAnotherStation {
        /// The uncertainty file.
        uncertainty: PathBuf,
        /// What its `station` field says.
        named: String,
        /// That, relative to the uncertainty file's folder.
        resolved: PathBuf,
        /// The station file used.
        station: PathBuf,
    },
    /// `summary.json` could not be serialised.
    #[error("{path}: {source}")]
    Json {
        /// The path.
        path: PathBuf,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
}

impl crate::outcome::Classify for PipelineError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            // A transparent variant's inner error is not in the source
            // chain (thiserror hands on the inner's own source): ask it.
            PipelineError::Acquisition(e) => e.outcome(),
            PipelineError::Spectral(e) => e.outcome(),
            PipelineError::Npy(e) => e.outcome(),
            PipelineError::SurfacesFile(e) => e.outcome(),
            PipelineError::Uncertainty(e) => e.outcome(),
            PipelineError::Station(e) => e.outcome(),
            PipelineError::NoSignal(_) => Some(Outcome::NoSignal),
            // The station file does not describe the plate: it is the
            // input to correct.
            PipelineError::UndeclaredWedge(_) => Some(Outcome::Input),
            PipelineError::Shape { .. }
            | PipelineError::Output { .. }
            | PipelineError::UncertaintyOfAnotherStation { .. } => Some(Outcome::Input),
            // Writing the result or a picture of it: a failure of its own
            // (exit 1; `plot` stands below `outcome`'s users, unclassed).
            PipelineError::Io { .. } | PipelineError::Json { .. } | PipelineError::Plot(_) => None,
        }
    }
}
