//! The exit status of `mfd`: one number per class of outcome, so that a
//! script can tell a complete result from an interrupted, refused or
//! inconsistent one. The table is documented in `--help` and the README.

use std::fmt;

/// Classes of outcome and their exit statuses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// Any failure not classed below.
    Failure,
    /// Bad command line (clap's own status).
    Usage,
    /// A file or option that is not valid input (names the file and field).
    Input,
    /// The data hold no measurable signal (dark frames, nothing where the
    /// station puts the element, too few points for the surfaces).
    NoSignal,
    /// The result contradicts the station (flagged, `--accept-inconsistent`
    /// to exit 0 anyway).
    Inconsistent,
    /// Camera or display failure.
    Device,
    /// Interrupted by the operator (Ctrl-C): the shell's 128 + SIGINT.
    Interrupted,
}

impl Class {
    /// The process exit status of this class.
    pub fn code(self) -> u8 {
        match self {
            Class::Failure => 1,
            Class::Usage => 2,
            Class::Input => 3,
            Class::NoSignal => 4,
            Class::Inconsistent => 5,
            Class::Device => 6,
            Class::Interrupted => 130,
        }
    }
}

/// An error with the class its exit status reports.
#[derive(Debug)]
pub struct Classified {
    /// The class.
    pub class: Class,
    /// What happened.
    pub error: anyhow::Error,
}

impl fmt::Display for Classified {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:#}", self.error)
    }
}

impl std::error::Error for Classified {}

/// `error`, to exit with `class`'s status.
pub fn classified(class: Class, error: anyhow::Error) -> anyhow::Error {
    anyhow::Error::new(Classified { class, error })
}

/// The class of an error: the outermost [`Classified`] in its chain, else
/// that of the outermost library error whose class is known (see
/// [`library_class`]), else [`Class::Failure`].
pub fn classify(err: &anyhow::Error) -> Class {
    err.chain()
        .find_map(|c| {
            c.downcast_ref::<Classified>()
                .map(|c| c.class)
                .or_else(|| library_class(c))
        })
        .unwrap_or(Class::Failure)
}

/// The class of one of the library's errors, where its type (and variant)
/// says it: bad input files and options → [`Class::Input`], nothing
/// measurable → [`Class::NoSignal`], camera and display faults →
/// [`Class::Device`]; `None` for the others (their causes decide).
fn library_class(e: &(dyn std::error::Error + 'static)) -> Option<Class> {
    use mfd::acquire::acquisition::AcquisitionError;
    use mfd::acquire::camera::CameraError;
    use mfd::acquire::display::DisplayError;
    use mfd::live::{LiveError, MeasurementError};
    use mfd::solve::spectral::SpectralError;
    use mfd::solve::surfaces::SurfaceError;
    if let Some(e) = e.downcast_ref::<MeasurementError>() {
        return match e {
            MeasurementError::ResumeMismatch { .. } | MeasurementError::Resolution { .. } => {
                Some(Class::Input)
            }
            _ => None,
        };
    }
    if let Some(e) = e.downcast_ref::<LiveError>() {
        return match e {
            LiveError::Reshoots { .. } | LiveError::FrameSize { .. } => Some(Class::Device),
            _ => None,
        };
    }
    if let Some(e) = e.downcast_ref::<CameraError>() {
        return Some(match e {
            CameraError::NotBuilt { .. } => Class::Input,
            _ => Class::Device,
        });
    }
    if let Some(e) = e.downcast_ref::<DisplayError>() {
        return Some(match e {
            DisplayError::NotBuilt { .. } => Class::Input,
            _ => Class::Device,
        });
    }
    if let Some(e) = e.downcast_ref::<AcquisitionError>() {
        return Some(match e {
            AcquisitionError::Io { source, .. } if !is_missing(source) => Class::Failure,
            AcquisitionError::Serialize { .. } => Class::Failure,
            _ => Class::Input,
        });
    }
    if let Some(e) = e.downcast_ref::<SurfaceError>() {
        return match e {
            SurfaceError::TooFewPoints { .. } => Some(Class::NoSignal),
            SurfaceError::Input { .. } => Some(Class::Input),
            _ => None,
        };
    }
    if let Some(e) = e.downcast_ref::<SpectralError>() {
        return match e {
            SpectralError::Schedule { .. }
            | SpectralError::Config { .. }
            | SpectralError::Statistics { .. } => Some(Class::Input),
            _ => None,
        };
    }
    if let Some(mfd::pipeline::PipelineError::UncertaintyOfAnotherStation { .. }) =
        e.downcast_ref::<mfd::pipeline::PipelineError>()
    {
        return Some(Class::Input);
    }
    let input = e.is::<mfd::optics::station::StationError>()
        || e.is::<mfd::optics::station::UncertaintyError>()
        || e.is::<mfd::acquire::schedule_file::ScheduleFileError>()
        || e.is::<mfd::acquire::patterns::ScheduleError>()
        || e.is::<mfd::formats::surfaces_file::SurfacesFileError>()
        || e.is::<mfd::formats::image_io::ImageError>()
        || e.is::<mfd::calibrate::session::SessionError>();
    input.then_some(Class::Input)
}

/// Whether an I/O error is a path that is not there (an input named wrong).
fn is_missing(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::NotFound | std::io::ErrorKind::PermissionDenied
    )
}
