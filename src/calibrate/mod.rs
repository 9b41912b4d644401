//! Calibrating a station from a point-source-microscope session
//! (`mfd-calibration/1`, spec `calibration.md`): the session's files, the
//! world frame it defines, the target centroids, the camera's resection,
//! the screen from the reference flat, and one joint adjustment with the
//! covariance of every degree of freedom it determines.
//!
//! It sits above the solvers: the reference flat's screen points come from
//! the spectral stage.

pub mod adjust;
pub mod calibration;
pub mod error;
pub mod input;
pub mod params;
pub mod report;
pub mod resect;
pub mod residuals;
pub mod session_file;
