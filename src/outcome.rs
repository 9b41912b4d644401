//! What kind of failure an error is, said by the error's own type: an
//! option's number out of the range the computation can take, bad input (a
//! file or option that is not valid, naming the file and field), no
//! measurable signal, or a device fault. The binary turns it into its
//! exit status (`cli::exit`); a script or the console can read it alike.
//! Each of the library's error types implements [`Classify`] beside its
//! definition; a variant with no class of its own answers `None`, and its
//! cause (the next error in the chain) decides.

/// A class of failure the operator acts on differently.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// An option (named by the error: `--noise`, `--frames`) whose value
    /// the computation cannot take: the caller's command line, checked
    /// where the library first sees the number (a range that depends on
    /// other options, or that the command line could not check alone).
    Range,
    /// A file or option that is not valid input.
    Input,
    /// The data hold no measurable signal.
    NoSignal,
    /// A camera or display fault.
    Device,
}

/// An error that knows its [`Outcome`].
pub trait Classify {
    /// This error's class; `None` where its cause decides.
    fn outcome(&self) -> Option<Outcome>;
}

/// [`Outcome::Input`] for a path that is not there or may not be read (an
/// input named wrong), `None` for other I/O failures.
pub fn io_outcome(e: &std::io::Error) -> Option<Outcome> {
    matches!(
        e.kind(),
        std::io::ErrorKind::NotFound | std::io::ErrorKind::PermissionDenied
    )
    .then_some(Outcome::Input)
}
