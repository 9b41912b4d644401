//! Calibrating a station from a point-source-microscope session
//! (`mfd-calibration/1`, spec `calibration.md`): the session's files, the
//! world frame it defines, the target centroids, the camera's resection,
//! the screen from the reference flat, and one joint adjustment with the
//! covariance of every degree of freedom it determines.
//!
//! It sits above the solvers: the reference flat's screen points come from
//! the spectral stage.
//!
//! - [`session_file`]: the serde types of `session.toml`, field for field.
//! - [`session`]: [`Session::load`], a validated session (paths resolved,
//!   the nominal station loaded), and [`SessionError`].
//! - [`frame`]: the world frame the session defines (reference plane from
//!   the flat points) and the element's pose, with covariances.
//! - [`centroid`]: the target spot's sub-pixel centroid in a camera frame,
//!   with its covariance.
//! - [`make`]: the template, the target positions to visit, capturing a
//!   target frame into the session.
//! - [`dlt`]: the direct linear transform (a projection matrix from
//!   world points and their pixels).
//! - [`check`]: everything missing or wrong in a session in progress, in
//!   the operator's words.
//! - [`input`]: [`input::CalibrationInput`], a session as the adjustment
//!   reads it (numbers in the stage frame).
//! - [`params`], [`residuals`], [`adjust`], [`resect`]: the unknowns (the
//!   frame's plane, the station's degrees of freedom), the residual blocks
//!   each against its own noise, one weighted adjustment with the choice of
//!   what to estimate, the camera by resection; [`screen_mark`]: where
//!   the PSM's focus stands on a marked screen pixel (cover glass).
//! - [`calibration`]: [`calibration::calibrate`], the single entry point
//!   (resection, screen, joint adjustment), and what it writes; [`report`].

pub mod adjust;
pub mod calibration;
pub mod centroid;
pub mod centroid_fit;
pub mod check;
mod check_layout;
mod check_marks;
pub mod dlt;
mod duplicates;
pub mod error;
pub mod frame;
pub mod from_session;
pub mod hold;
pub mod input;
pub mod make;
pub mod params;
pub mod pictures;
pub mod pictures_sensor;
pub mod report;
pub mod resect;
pub mod residuals;
mod rules;
pub mod screen_mark;
pub mod session;
pub mod session_file;
pub mod simulate;
mod spot_background;
pub mod spread;
pub mod target_grid;
mod valley;
pub mod weak;

pub use rules::{station_size_mm, PLAUSIBLE_STAGE_STD_UM, UNIT_MARGIN};
pub use session::{ObservedTarget, Session, SessionError, Target, TargetObservation};
