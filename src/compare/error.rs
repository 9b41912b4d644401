//! The comparison's errors: every one names the file and, for a header,
//! the field, with what was expected.

use std::path::PathBuf;

/// What went wrong reading or comparing an interferometer map.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A header field has a value the format does not allow.
    #[error("{path}: header field {field} is {found}, expected {expected}")]
    Header {
        /// The file.
        path: PathBuf,
        /// The field's name in the format's documentation.
        field: &'static str,
        /// What the file has.
        found: String,
        /// What the format allows.
        expected: String,
    },
    /// Not a plain file, or longer than its header says: read no further
    /// than the header's size, so a link to a device or a file with
    /// something appended is named, not read until memory runs out.
    #[error("{path}: {problem}")]
    Length {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the sizes.
        problem: String,
    },
    /// The file ends before the data its header announces.
    #[error("{path}: {what} needs {expected} bytes from offset {offset}, the file has {found}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What was being read.
        what: &'static str,
        /// Where it starts.
        offset: usize,
        /// Bytes it needs.
        expected: usize,
        /// Bytes the file has from there.
        found: usize,
    },
    /// A CSV line is not a row of numbers.
    #[error("{path}: line {line}: {reason}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// An array or HDF5 item is not what a height map needs.
    #[error("{path}: {item}: {reason}")]
    Content {
        /// The file.
        path: PathBuf,
        /// The array, dataset or attribute.
        item: String,
        /// What is wrong and what was expected.
        reason: String,
    },
    /// The file's kind is not known from its name.
    #[error(
        "{path}: unknown interferometer format (expected .dat (Zygo MetroPro), .datx (Zygo, \
         HDF5), .npy or .csv)"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A `.datx` file was given to a build without HDF5.
    #[error("{path}: reading .datx needs mfd built with the cargo feature `datx` (HDF5)")]
    NoDatx {
        /// The file.
        path: PathBuf,
    },
    /// The map's pixel size is not known and cannot be set from the aperture.
    #[error("{path}: no pixel size: give --pixel-mm")]
    NoPixelSize {
        /// The file.
        path: PathBuf,
    },
    /// Too little of the map falls on the measured aperture.
    #[error(
        "{path}: only {points} map pixels fall on the measured aperture ({fraction:.2} of it): \
         check the registration (--center-px, --pixel-mm, --radius-px)"
    )]
    Coverage {
        /// The file.
        path: PathBuf,
        /// Valid map pixels on the aperture.
        points: usize,
        /// Their share of the aperture's area.
        fraction: f64,
    },
    /// The surface to compare is not in `surfaces.json`.
    #[error("{path}: the {surface} surface was not reconstructed: nothing to compare")]
    NoSurface {
        /// The surfaces file.
        path: PathBuf,
        /// `front` or `back`.
        surface: String,
    },
    /// The Zernike fit failed.
    #[error("{path}: Zernike fit of the map: {source}")]
    Fit {
        /// The map.
        path: PathBuf,
        /// The fit's error.
        #[source]
        source: crate::optics::zernike::ZernikeError,
    },
    /// An NPY file could not be read.
    #[error(transparent)]
    Npy(#[from] crate::formats::npy::NpyError),
    /// `surfaces.json` could not be read.
    #[error(transparent)]
    Surfaces(#[from] crate::formats::surfaces_file::SurfacesFileError),
    /// A picture could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
}

impl crate::outcome::Classify for CompareError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            CompareError::Io { source, .. } => crate::outcome::io_outcome(source),
            CompareError::Npy(e) => e.outcome(),
            CompareError::Surfaces(e) => e.outcome(),
            // Drawing a picture: a failure of its own (exit 1).
            CompareError::Plot(_) => None,
            CompareError::Fit { source, .. } => source.outcome(),
            // Every other variant names the map or surfaces file and what
            // in it (or in the registration options) is not valid.
            _ => Some(Outcome::Input),
        }
    }
}
