//! `[camera] aspect_ratio` (proposal `mfd-station/3`,
//! `docs/proposals/aspect.md`): the camera's `fy / fx`, read and checked.

use std::path::Path;

use super::file::STATION_FORMAT_V3;
use super::StationError;

/// The range of `fy / fx` a camera's pixels may have. Calibrated machine
/// vision cameras give 1 ± 0.01 (OpenCSP's cameras 1.001); anamorphic
/// formats reach 0.75–1.33. A value outside [0.5, 2] is a slip (the inverse
/// ratio typed in percent, fx and fy in different units), not a camera.
pub const ASPECT_RANGE: [f64; 2] = [0.5, 2.0];

/// The declared aspect ratio, checked: finite, within [`ASPECT_RANGE`], and
/// in a file of the proposal's format; `None` when the field is absent.
pub(super) fn checked(
    path: &Path,
    format: &str,
    aspect: Option<f64>,
) -> Result<Option<f64>, StationError> {
    let Some(a) = aspect else {
        return Ok(None);
    };
    let fail = |problem: String| {
        Err(StationError::Invalid {
            path: path.to_path_buf(),
            field: "camera.aspect_ratio",
            problem,
        })
    };
    if format != STATION_FORMAT_V3 {
        return fail(format!(
            "the aspect ratio is a field of the proposal \"{STATION_FORMAT_V3}\" \
             (docs/proposals/aspect.md), not of \"{format}\": write format = \
             \"{STATION_FORMAT_V3}\" to use it"
        ));
    }
    let [lo, hi] = ASPECT_RANGE;
    if !(a.is_finite() && (lo..=hi).contains(&a)) {
        return fail(format!(
            "expected fy / fx, a finite ratio within [{lo}, {hi}], found {a} (from OpenCV's \
             camera matrix: fy divided by fx, both in pixels)"
        ));
    }
    Ok(Some(a))
}
