//! Zernike polynomials for surface description: Noll ordering, Noll (RMS)
//! normalisation, exact evaluation with Cartesian gradients, and blocked
//! least-squares fitting of heights and slopes.
//!
//! # Conventions (fixed by the interchange spec)
//!
//! ```text
//!            +y (world, mm)
//!             ^
//!             |      * (x, y)
//!             |     /
//!             |    / r          rho   = r / radius_mm
//!             |   /             theta = atan2(y - cy, x - cx),
//!             |  /  theta               from +x towards +y
//!  -----------+-------------> +x (world, mm)
//!        center_mm = (cx, cy)
//! ```
//!
//! * **Ordering**: Noll. j = 1 piston, 2 x-tilt, 3 y-tilt, 4 defocus, 5 and 6
//!   astigmatism, 7 and 8 coma, ..., 11 primary spherical. Coefficient vector
//!   index k holds Noll j = k + 1. [`noll_to_nm`] gives `(n, m)` with m > 0
//!   for cosine, m < 0 for sine and m = 0 for rotationally symmetric terms.
//! * **Normalisation**: Noll / RMS, orthonormal on the unit disk with respect
//!   to `(1/pi) dA`:
//!   `Z_j = sqrt(n+1) R_n^0(rho)` for m = 0,
//!   `Z_j = sqrt(2(n+1)) R_n^|m|(rho) cos(|m| theta)` for even j (m > 0),
//!   `Z_j = sqrt(2(n+1)) R_n^|m|(rho) sin(|m| theta)` for odd j (m < 0).
//! * **Surface**: `W(x, y) = sum_j c_j Z_j(x, y)` with `c_j` in **nm**.
//! * **Units**: lengths inside the library are mm. [`ZernikeSurface`]
//!   returns heights in mm (nm x 1e-6) and gradients dimensionless (mm/mm);
//!   [`ZernikeBasis`] returns dimensionless values and derivatives per mm;
//!   [`fit_heights`] / [`fit_slopes`] take heights in mm / slopes in mm/mm and
//!   return coefficients in nm.
//! * **Outside the disk** (rho > 1) the polynomial is still the surface:
//!   nothing is clamped or set to NaN there.
//!
//! # Numerics
//! `R_n^m(rho) = rho^m Q_k(rho^2)` with a Jacobi three-term recurrence in
//! `k = (n - m)/2` (no factorial sums, exact to f64 rounding far beyond
//! n = 20), the angular part from `(X + iY)^m` and gradients from
//! `d/dX [Q (X+iY)^m] = 2X Q' (X+iY)^m + m Q (X+iY)^(m-1)` (likewise in Y
//! with a factor i), which is regular at the centre. Fits use incremental
//! Householder QR over row blocks, so millions of points need only
//! O(n_terms^2) memory.

mod basis;
mod error;
mod fit;
mod indices;
mod qr;
mod radial;
mod random;
mod surface;

#[cfg(test)]
mod test_util;
#[cfg(test)]
mod tests_eval;
#[cfg(test)]
mod tests_fit;
#[cfg(test)]
mod tests_gradient;

pub use basis::ZernikeBasis;
pub use error::ZernikeError;
pub use fit::{fit_heights, fit_slopes, ZernikeFit};
pub use indices::{nm_to_noll, noll_to_nm, terms_up_to_order};
pub use radial::radial_polynomial;
pub use random::RandomSurfaceSpec;
pub use surface::ZernikeSurface;

/// Highest radial order a basis may hold (recurrence verified to n = 100).
pub const MAX_RADIAL_ORDER: u32 = 100;

/// Largest number of basis terms: all terms up to [`MAX_RADIAL_ORDER`]
/// (5151).
pub const MAX_TERMS: usize = (MAX_RADIAL_ORDER as usize + 1) * (MAX_RADIAL_ORDER as usize + 2) / 2;

/// Fits whose weighted design matrix has a larger 2-norm condition number
/// are rejected with [`ZernikeError::IllConditioned`].
pub const MAX_CONDITION_NUMBER: f64 = 1e12;

/// Nanometres per millimetre.
const NM_PER_MM: f64 = 1e6;
/// Millimetres per nanometre.
const MM_PER_NM: f64 = 1e-6;
