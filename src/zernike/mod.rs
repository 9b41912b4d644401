//! Zernike polynomials: Noll ordering, RMS (Noll) normalisation, evaluation
//! with gradients, and least-squares fitting of heights and slopes.
//!
//! ```text
//!        y ↑            Z_j(ρ, θ) = sqrt(n+1) R_n^0(ρ)                 (m = 0)
//!          │  ρ,θ            = sqrt(2(n+1)) R_n^m(ρ) cos mθ   (j even)
//!    ──────●──── → x         = sqrt(2(n+1)) R_n^m(ρ) sin mθ   (j odd)
//!     centre_mm   ρ = r / radius_mm, θ from +x towards +y (world frame)
//! ```
//!
//! A surface is `W = Σ_j c_j Z_j` with `c_j` in nanometres; coefficient index
//! k holds Noll j = k + 1. Heights come back in millimetres, gradients
//! dimensionless (mm/mm). The polynomial is the surface also outside ρ = 1:
//! nothing is clamped there.

mod basis;
mod fit;
#[cfg(test)]
mod tests;

pub use basis::{nm_to_noll, noll_to_nm, terms_up_to_order};
pub use fit::{fit_heights, fit_slopes, ZernikeFit};

use basis::Layout;

/// Nanometres per millimetre.
const NM_PER_MM: f64 = 1e6;

/// What can go wrong with Zernike bases and fits.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ZernikeError {
    /// Noll indices start at 1.
    #[error("Noll index j = {j} is invalid (j starts at 1)")]
    InvalidIndex {
        /// The index given.
        j: usize,
    },
    /// `(n, m)` is not a Zernike order.
    #[error("(n, m) = ({n}, {m}) is not a Zernike order (need |m| ≤ n, n − |m| even)")]
    InvalidOrder {
        /// Radial order.
        n: u32,
        /// Signed azimuthal order.
        m: i32,
    },
    /// The normalisation radius must be finite and positive, the centre finite.
    #[error(
        "Zernike radius {radius_mm} mm / centre {center_mm:?} mm is invalid (radius > 0, finite)"
    )]
    InvalidRadius {
        /// The radius given, mm.
        radius_mm: f64,
        /// The centre given, mm.
        center_mm: [f64; 2],
    },
    /// A basis needs at least one term.
    #[error("a Zernike basis needs at least one term")]
    NoTerms,
    /// Arrays that must have equal lengths do not.
    #[error("{what}: expected {expected} values, found {found}")]
    LengthMismatch {
        /// Which array.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// A coefficient is NaN or infinite.
    #[error("coefficient {index} (Noll j = {}) is not finite: {value}", index + 1)]
    NonFinite {
        /// Index of the coefficient.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// Fewer data rows than unknowns.
    #[error("{rows} data rows cannot determine {unknowns} Zernike terms")]
    TooFewPoints {
        /// Rows of data.
        rows: usize,
        /// Unknown coefficients.
        unknowns: usize,
    },
    /// The design is (numerically) rank deficient.
    #[error(
        "Zernike fit is ill-conditioned: condition number {condition_number:.3e} (limit 1e12)"
    )]
    IllConditioned {
        /// Ratio of largest to smallest singular value of the design.
        condition_number: f64,
    },
}

/// The Zernike basis of a given size on a given disk.
#[derive(Debug, Clone, PartialEq)]
pub struct ZernikeBasis {
    n_terms: usize,
    radius_mm: f64,
    center_mm: [f64; 2],
    layout: Layout,
}

impl ZernikeBasis {
    /// Noll terms j = 1 … `n_terms` on the disk of `radius_mm` about `center_mm`.
    ///
    /// # Errors
    /// [`ZernikeError::NoTerms`] or [`ZernikeError::InvalidRadius`].
    pub fn new(n_terms: usize, radius_mm: f64, center_mm: [f64; 2]) -> Result<Self, ZernikeError> {
        if n_terms == 0 {
            return Err(ZernikeError::NoTerms);
        }
        if !(radius_mm.is_finite() && radius_mm > 0.0 && center_mm.iter().all(|c| c.is_finite())) {
            return Err(ZernikeError::InvalidRadius {
                radius_mm,
                center_mm,
            });
        }
        Ok(ZernikeBasis {
            n_terms,
            radius_mm,
            center_mm,
            layout: Layout::new(n_terms),
        })
    }

    /// Number of terms.
    pub fn n_terms(&self) -> usize {
        self.n_terms
    }

    /// Normalisation radius, mm.
    pub fn radius_mm(&self) -> f64 {
        self.radius_mm
    }

    /// Centre `[x, y]`, mm.
    pub fn center_mm(&self) -> [f64; 2] {
        self.center_mm
    }

    /// Normalised coordinates (X, Y) = ((x, y) − centre) / radius.
    #[inline]
    fn normalise(&self, x_mm: f64, y_mm: f64) -> (f64, f64) {
        (
            (x_mm - self.center_mm[0]) / self.radius_mm,
            (y_mm - self.center_mm[1]) / self.radius_mm,
        )
    }

    /// All basis values (dimensionless) and their derivatives per mm at
    /// `(x_mm, y_mm)`. Each slice must hold `n_terms` values.
    ///
    /// # Panics
    /// If a slice is shorter than `n_terms` (a programming error).
    pub fn eval_into(
        &self,
        x_mm: f64,
        y_mm: f64,
        values: &mut [f64],
        d_dx: &mut [f64],
        d_dy: &mut [f64],
    ) {
        let (x, y) = self.normalise(x_mm, y_mm);
        let s = 1.0 / self.radius_mm;
        self.layout.for_each(x, y, |k, v, dx, dy| {
            values[k] = v;
            d_dx[k] = dx * s;
            d_dy[k] = dy * s;
        });
    }

    /// All basis values at `(x_mm, y_mm)` into `values` (`n_terms` long).
    pub fn eval_values_into(&self, x_mm: f64, y_mm: f64, values: &mut [f64]) {
        let (x, y) = self.normalise(x_mm, y_mm);
        self.layout.for_each(x, y, |k, v, _, _| values[k] = v);
    }
}

/// A surface `W = Σ c_j Z_j`, coefficients in nm.
#[derive(Debug, Clone, PartialEq)]
pub struct ZernikeSurface {
    basis: ZernikeBasis,
    coefficients_nm: Vec<f64>,
    flat: bool,
}

impl ZernikeSurface {
    /// A surface from a basis and as many coefficients (nm).
    ///
    /// # Errors
    /// [`ZernikeError::LengthMismatch`] or [`ZernikeError::NonFinite`].
    pub fn new(basis: ZernikeBasis, coefficients_nm: Vec<f64>) -> Result<Self, ZernikeError> {
        if coefficients_nm.len() != basis.n_terms {
            return Err(ZernikeError::LengthMismatch {
                what: "Zernike coefficients",
                expected: basis.n_terms,
                found: coefficients_nm.len(),
            });
        }
        if let Some((index, &value)) = coefficients_nm
            .iter()
            .enumerate()
            .find(|(_, c)| !c.is_finite())
        {
            return Err(ZernikeError::NonFinite { index, value });
        }
        let flat = coefficients_nm.iter().all(|&c| c == 0.0);
        Ok(ZernikeSurface {
            basis,
            coefficients_nm,
            flat,
        })
    }

    /// The plane `W = 0` (one zero piston term).
    ///
    /// # Errors
    /// [`ZernikeError::InvalidRadius`].
    pub fn flat(radius_mm: f64, center_mm: [f64; 2]) -> Result<Self, ZernikeError> {
        Self::new(ZernikeBasis::new(1, radius_mm, center_mm)?, vec![0.0])
    }

    /// Whether every coefficient is zero.
    pub fn is_flat(&self) -> bool {
        self.flat
    }

    /// The basis.
    pub fn basis(&self) -> &ZernikeBasis {
        &self.basis
    }

    /// Coefficients, nm (index k = Noll j − 1).
    pub fn coefficients_nm(&self) -> &[f64] {
        &self.coefficients_nm
    }

    /// Number of terms.
    pub fn n_terms(&self) -> usize {
        self.basis.n_terms
    }

    /// Height W(x, y), mm.
    pub fn height_mm(&self, x_mm: f64, y_mm: f64) -> f64 {
        self.height_and_gradient(x_mm, y_mm).0
    }

    /// Height (mm) and gradient `(∂W/∂x, ∂W/∂y)` (dimensionless) at `(x_mm, y_mm)`.
    #[inline]
    pub fn height_and_gradient(&self, x_mm: f64, y_mm: f64) -> (f64, f64, f64) {
        if self.flat {
            return (0.0, 0.0, 0.0);
        }
        let (x, y) = self.basis.normalise(x_mm, y_mm);
        let c = &self.coefficients_nm;
        let (mut w, mut wx, mut wy) = (0.0, 0.0, 0.0);
        self.basis.layout.for_each(x, y, |k, v, dx, dy| {
            w += c[k] * v;
            wx += c[k] * dx;
            wy += c[k] * dy;
        });
        let s = 1.0 / NM_PER_MM;
        (
            w * s,
            wx * s / self.basis.radius_mm,
            wy * s / self.basis.radius_mm,
        )
    }

    /// RMS of the surface over the unit disk without piston (and without tilt
    /// when `remove_tilt`), nm: by orthonormality, the root sum of squares of
    /// the remaining coefficients.
    pub fn rms_nm(&self, remove_tilt: bool) -> f64 {
        let skip = if remove_tilt { 3 } else { 1 };
        self.coefficients_nm
            .iter()
            .skip(skip)
            .map(|c| c * c)
            .sum::<f64>()
            .sqrt()
    }
}
