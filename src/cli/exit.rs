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
/// [`Class::Failure`].
pub fn classify(err: &anyhow::Error) -> Class {
    err.chain()
        .find_map(|c| c.downcast_ref::<Classified>().map(|c| c.class))
        .unwrap_or(Class::Failure)
}
