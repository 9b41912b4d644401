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
    /// to exit 0 anyway), or a surface stage stopped at its iteration limit
    /// short of its σ (flagged, `--accept-unconverged`).
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

/// The class of a library error held by reference (one a result keeps, to
/// be reported in a message of its own): its own or its causes', else
/// [`Class::Failure`].
pub fn class_of(e: &(dyn std::error::Error + 'static)) -> Class {
    let mut next = Some(e);
    while let Some(c) = next {
        if let Some(class) = library_class(c) {
            return class;
        }
        next = c.source();
    }
    Class::Failure
}

/// `message` for the library error `cause` (kept by reference), to exit
/// with `cause`'s class.
pub fn like(cause: &(dyn std::error::Error + 'static), message: String) -> anyhow::Error {
    classified(class_of(cause), anyhow::Error::msg(message))
}

/// `error` as bad command line: an option missing or given wrong where clap
/// cannot say it (exit 2).
pub fn usage(error: anyhow::Error) -> anyhow::Error {
    classified(Class::Usage, error)
}

/// `error` as bad input: a file or option that is not valid (exit 3).
pub fn input(error: anyhow::Error) -> anyhow::Error {
    classified(Class::Input, error)
}

/// The class of one of the library's errors, as its type says it
/// ([`mfd::outcome::Classify`], implemented beside each error's
/// definition); `None` for the others and for variants whose cause
/// decides. The list names the library's error types that have a class.
fn library_class(e: &(dyn std::error::Error + 'static)) -> Option<Class> {
    use mfd::outcome::{Classify, Outcome};
    /// The first of `types` that `e` is, asked for its outcome.
    macro_rules! outcome_of {
        ($($t:ty),+ $(,)?) => {
            $(if let Some(e) = e.downcast_ref::<$t>() {
                return e.outcome().map(|o| match o {
                    Outcome::Range => Class::Usage,
                    Outcome::Input => Class::Input,
                    Outcome::NoSignal => Class::NoSignal,
                    Outcome::Device => Class::Device,
                });
            })+
        };
    }
    // Every error type of the library with a `Classify` impl (the test
    // `exit_statuses::every_library_error_has_a_class` keeps this whole).
    outcome_of!(
        mfd::acquire::acquisition::AcquisitionError,
        mfd::acquire::camera::CameraError,
        mfd::acquire::camera::convert::RangeError,
        mfd::acquire::camera::convert::SizeError,
        mfd::acquire::display::DisplayError,
        mfd::acquire::patterns::ScheduleError,
        mfd::acquire::schedule_file::ScheduleFileError,
        mfd::budget::picture::PictureError,
        mfd::budget::refine::RefineError,
        mfd::budget::scene::BudgetError,
        mfd::calibrate::centroid::CentroidError,
        mfd::calibrate::error::CalibrationError,
        mfd::calibrate::frame::FrameError,
        mfd::calibrate::from_session::SessionSolveError,
        mfd::calibrate::make::MakeError,
        mfd::calibrate::session::SessionError,
        mfd::compare::CompareError,
        mfd::console::ConsoleError,
        mfd::console::preview::PreviewError,
        mfd::formats::image_io::ImageError,
        mfd::formats::npy::NpyError,
        mfd::formats::surfaces_file::SurfacesFileError,
        mfd::formats::surfaces_file::SurfacesOrFlatError,
        mfd::limits::TooLarge,
        mfd::live::LiveError,
        mfd::live::MeasurementError,
        mfd::optics::outline::OutlineError,
        mfd::optics::station::StationError,
        mfd::optics::station::UncertaintyError,
        mfd::optics::zernike::ZernikeError,
        mfd::pipeline::PipelineError,
        mfd::plan::PlanError,
        mfd::report::page::ReportError,
        mfd::sim::SimError,
        mfd::solve::direct::run::DirectError,
        mfd::solve::spectral::FeedError,
        mfd::solve::spectral::phase::curve::CurveError,
        mfd::solve::spectral::phase::curve::ProfileResponseError,
        mfd::solve::spectral::statistics::StatisticsError,
        mfd::solve::spectral::SpectralError,
        mfd::solve::surfaces::SurfaceError,
    );
    None
}
