//! Comparison with an interferometer: Fizeau height maps (Zygo MetroPro `.dat`, Zygo `.datx`, NPY/CSV), registration on the measured aperture, the same Zernike fit, and the difference.
//!
//! What the paper shows beside every measurement (Fig. 14(c), 18, 21): the
//! interferometer's map and ours side by side, their difference, and both
//! sets of Zernike coefficients term by term with mfd's error bars. The
//! steps:
//!
//! 1. read the map ([`load`]: [`dat`], `datx` behind the cargo feature
//!    `datx`, [`plain`] for NPY and CSV) into an [`InterferometerMap`]:
//!    heights in nm, row 0 at the top, NaN where the instrument had no data;
//! 2. register it on the measured aperture ([`register`]): the map pixel of
//!    the aperture's centre, the scale, the rotation and a mirror flip, each
//!    given or fitted;
//! 3. fit the same Zernike terms over the same aperture, take the difference
//!    point by point, remove piston and tilt, and give its RMS
//!    ([`compare`], a [`Comparison`]).
//!
//! The Zernike fit is the library's ([`crate::optics::zernike::fit_heights`]);
//! the rotation search acts on the fitted coefficients in closed form (a
//! rotation turns each cos/sin pair by m·θ), which no crate does for us.

pub mod dat;
#[cfg(feature = "datx")]
pub mod datx;
mod error;
mod fit;
mod map;
pub mod pictures;
pub mod plain;
pub mod register;

pub use error::CompareError;
pub use fit::{compare, Comparison, ComparisonMaps, TermComparison, COMPARISON_FORMAT};
pub use map::{load, InterferometerMap, LoadOptions};
pub use register::{Registration, RegistrationOptions};
