//! The calibration report's pictures: each target's reprojection residual
//! and the reference flat's fringe-map residual over the sensor, on the
//! calibrated station — what an operator looks at to see whether a reading
//! or a region of the flat disagrees with the rest.

use std::path::{Path, PathBuf};

use super::calibration::Calibration;
use super::input::CalibrationInput;
use super::residuals::flat_reflection_uv;
use crate::report::plot::{height_map, line_plot_png, Format, HeightMap, Panel, PlotError, Series};

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

/// Writes `targets.png` (residual x and y per target, px) and
/// `flat_residuals.png` (each used flat pixel's `u` residual over its σ: a
/// region or a pattern that stands out of the ±1 noise is a model error)
/// into `dir`.
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
        let e = (p.screen_px.x - pred.x) / p.screen_cov_px2[(0, 0)].sqrt();
        let k = (p.pixel[1] / cell) as usize * w + (p.pixel[0] / cell) as usize;
        map[k] = e;
    }
    let flat = dir.join("flat_residuals.png");
    height_map(
        &flat,
        Format::Png,
        &HeightMap {
            values: &map,
            width: w,
            height: h,
            title: "reference flat: (measured − calibrated) u / σ over the sensor",
            unit: "σ",
            extent: None,
        },
    )?;
    Ok(vec![targets, flat])
}
