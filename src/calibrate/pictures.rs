//! The calibration report's pictures: each target's reprojection residual,
//! the reprojected targets on the sensor at each height
//! ([`super::pictures_sensor`]), and the reference flat's fringe-map
//! residual over the sensor in u and in v, on the calibrated station —
//! what an operator looks at to see whether a reading or a region of the
//! flat disagrees with the rest.

use std::path::{Path, PathBuf};

use super::calibration::Calibration;
use super::input::CalibrationInput;
use super::residuals::flat_reflection_uv;
use crate::plot::{height_map, line_plot_png, Format, HeightMap, Panel, PlotError, Series};

/// The flat map's picture has at most this many columns (the sensor's
/// pixels are gathered into cells of equal size).
const MAP_COLUMNS: u32 = 400;

/// Each target's residual `measured − reprojected` (px), in session order.
pub fn target_residuals(cal: &Calibration, input: &CalibrationInput) -> Vec<[f64; 2]> {
    input
        .targets
        .iter()
        .map(|t| {
            let world = cal.frame.to_world(&t.stage_mm);
            match cal.station.camera.project(&world) {
                Some(p) => [t.pixel.x - p.x, t.pixel.y - p.y],
                None => [f64::NAN; 2],
            }
        })
        .collect()
}

/// Writes into `dir`: `targets.png` (residual x and y per target, px),
/// `targets_on_sensor.png` (measured and reprojected targets with scaled
/// residual arrows, a panel per height), `flat_residuals.png` and
/// `flat_residuals_v.png` (each used flat pixel's `u`, `v` residual over
/// its σ: a region or a pattern that stands out of the ±1 noise is a model
/// error).
///
/// # Errors
/// [`PlotError`] naming the file that could not be written.
pub fn write_pictures(
    cal: &Calibration,
    input: &CalibrationInput,
    dir: &Path,
) -> Result<Vec<PathBuf>, PlotError> {
    let res = target_residuals(cal, input);
    let xs: Vec<(f64, f64)> = res
        .iter()
        .enumerate()
        .map(|(k, r)| (k as f64, r[0]))
        .collect();
    let ys: Vec<(f64, f64)> = res
        .iter()
        .enumerate()
        .map(|(k, r)| (k as f64, r[1]))
        .collect();
    let targets = dir.join("targets.png");
    line_plot_png(
        &targets,
        &[Panel {
            title: "target reprojection residual (measured − calibrated)",
            x_label: "target_point index",
            y_label: "residual, px",
            log_x: false,
            log_y: false,
            series: &[
                Series {
                    label: "x (column)",
                    points: &xs,
                },
                Series {
                    label: "y (row)",
                    points: &ys,
                },
            ],
        }],
    )?;
    let sensor = dir.join("targets_on_sensor.png");
    super::pictures_sensor::targets_on_sensor_png(cal, input, &sensor)?;
    let u = dir.join("flat_residuals.png");
    flat_map(cal, input, 0, &u)?;
    let v = dir.join("flat_residuals_v.png");
    flat_map(cal, input, 1, &v)?;
    Ok(vec![targets, sensor, u, v])
}

/// The flat's residual over σ of coordinate `axis` (0: u, 1: v) over the
/// sensor, written to `path`.
fn flat_map(
    cal: &Calibration,
    input: &CalibrationInput,
    axis: usize,
    path: &Path,
) -> Result<(), PlotError> {
    let cam = &cal.station.camera;
    // The flat's pixels may be a grid of every s-th pixel: cells of s.
    let grid = input
        .flat_screen
        .windows(2)
        .filter(|w| w[0].pixel[1] == w[1].pixel[1])
        .map(|w| w[1].pixel[0].saturating_sub(w[0].pixel[0]))
        .filter(|&d| d > 0)
        .min()
        .unwrap_or(1);
    let cell = cam.width.div_ceil(MAP_COLUMNS).max(grid);
    let (w, h) = (
        cam.width.div_ceil(cell) as usize,
        cam.height.div_ceil(cell) as usize,
    );
    let mut map = vec![f64::NAN; w * h];
    for p in &input.flat_screen {
        let Some(pred) = flat_reflection_uv(&cal.station, p.pixel[0], p.pixel[1]) else {
            continue;
        };
        let e = (p.screen_px[axis] - pred[axis]) / p.screen_cov_px2[(axis, axis)].sqrt();
        let k = (p.pixel[1] / cell) as usize * w + (p.pixel[0] / cell) as usize;
        map[k] = e;
    }
    let title = if axis == 0 {
        "reference flat: (measured − calibrated) u / σ over the sensor"
    } else {
        "reference flat: (measured − calibrated) v / σ over the sensor"
    };
    height_map(
        path,
        Format::Png,
        &HeightMap {
            values: &map,
            width: w,
            height: h,
            title,
            unit: "σ",
            extent: None,
        },
    )?;
    Ok(())
}
