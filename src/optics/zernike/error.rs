//! The error type of the Zernike module.

/// Everything that can go wrong when building a Zernike basis or surface,
/// converting indices, or fitting data. Every variant carries the offending
/// values so that callers can report them without parsing text.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ZernikeError {
    /// A Noll index outside `1 ..` (or too large to represent).
    #[error("invalid Noll index j = {j}: Noll indices start at 1")]
    InvalidIndex {
        /// The index given.
        j: usize,
    },
    /// `(n, m)` is not a Zernike order: needs `|m| <= n`, `n - |m|` even, and
    /// `n` within the supported range.
    #[error("(n, m) = ({n}, {m}) is not a valid Zernike order (need |m| <= n, n - |m| even)")]
    InvalidOrder {
        /// Radial order n.
        n: u32,
        /// Signed azimuthal order m (> 0 cos, < 0 sin, 0 symmetric).
        m: i32,
    },
    /// The normalisation radius must be finite and strictly positive.
    #[error("invalid normalisation radius {radius_mm} mm: must be finite and > 0")]
    InvalidRadius {
        /// The radius given, mm.
        radius_mm: f64,
    },
    /// The disk centre must be finite.
    #[error("invalid disk centre ({}, {}) mm: must be finite", center_mm[0], center_mm[1])]
    InvalidCenter {
        /// The centre given, mm (world x, y).
        center_mm: [f64; 2],
    },
    /// The number of basis terms is zero or above the supported maximum.
    #[error("invalid number of Zernike terms {n_terms}: must be between 1 and {max}")]
    InvalidTermCount {
        /// The number of terms asked for.
        n_terms: usize,
        /// The largest supported number of terms.
        max: usize,
    },
    /// Two arrays that must have equal lengths do not.
    #[error("{what}: expected {expected} values, found {actual}")]
    LengthMismatch {
        /// Which array.
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length given.
        actual: usize,
    },
    /// An input value is NaN or infinite.
    #[error("{what}[{index}] is not finite")]
    NonFinite {
        /// Which array.
        what: &'static str,
        /// Index of the offending element.
        index: usize,
    },
    /// A fitting weight is negative, NaN or infinite.
    #[error("weights[{index}] = {weight} is invalid: weights must be finite and >= 0")]
    InvalidWeight {
        /// Index of the offending weight.
        index: usize,
        /// Its value.
        weight: f64,
    },
    /// Fewer equations than unknown coefficients.
    #[error("{points} usable points give {equations} equations, too few for {unknowns} unknowns")]
    TooFewPoints {
        /// Points with a positive weight.
        points: usize,
        /// Equations they give (points for heights, 2 x points for slopes).
        equations: usize,
        /// Unknown coefficients.
        unknowns: usize,
    },
    /// The weighted design matrix is numerically rank deficient.
    #[error(
        "ill-conditioned Zernike fit: condition number {condition_number:.3e} exceeds {:.0e}",
        super::MAX_CONDITION_NUMBER
    )]
    IllConditioned {
        /// Ratio of the largest to the smallest singular value of the weighted
        /// design matrix (infinite when a singular value is zero).
        condition_number: f64,
    },
}

impl crate::outcome::Classify for ZernikeError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            // Indices, orders, radii, centres and term counts come from
            // files and options; non-finite values from the data.
            ZernikeError::InvalidIndex { .. }
            | ZernikeError::InvalidOrder { .. }
            | ZernikeError::InvalidRadius { .. }
            | ZernikeError::InvalidCenter { .. }
            | ZernikeError::InvalidTermCount { .. }
            | ZernikeError::NonFinite { .. } => Some(Outcome::Input),
            ZernikeError::TooFewPoints { .. } => Some(Outcome::NoSignal),
            // Lengths and weights are the program's own: a bug.
            ZernikeError::LengthMismatch { .. }
            | ZernikeError::InvalidWeight { .. }
            | ZernikeError::IllConditioned { .. } => None,
        }
    }
}
