//! The reprojected targets on the sensor: for each height the targets were
//! placed at, the sensor with each target's measured centroid, its position
//! as the calibrated station projects it, and the residual between them as
//! an arrow scaled up by a stated factor (residuals are hundredths of a
//! pixel on a sensor of a thousand).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::calibration::Calibration;
use super::input::CalibrationInput;
use crate::plot::{register_font, PlotError, FAMILY};

/// Targets whose world heights differ by less than this share a layer, mm
/// (layers are placed tens of millimetres apart; the stage noise is µm).
const LAYER_GAP_MM: f64 = 5.0;

/// Width of one layer's panel, px.
const PANEL_PX: u32 = 560;

/// The longest arrow, as a fraction of the sensor's width.
const LONGEST_ARROW: f64 = 0.08;

/// One target as the picture shows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reprojected {
    /// World height of the target, mm.
    pub height_mm: f64,
    /// Measured centroid, px.
    pub measured: [f64; 2],
    /// Projected by the calibrated station, px.
    pub predicted: [f64; 2],
}

/// Each target's measured and reprojected position (targets behind the
/// calibrated camera left out).
pub fn reprojected(cal: &Calibration, input: &CalibrationInput) -> Vec<Reprojected> {
    input
        .targets
        .iter()
        .filter_map(|t| {
            let world = cal.frame.to_world(&t.stage_mm);
            let p = cal.station.camera.project(&world)?;
            Some(Reprojected {
                height_mm: world.z,
                measured: [t.pixel.x, t.pixel.y],
                predicted: [p.x, p.y],
            })
        })
        .collect()
}

/// The targets grouped by height, lowest first.
pub fn layers(targets: &[Reprojected]) -> Vec<Vec<Reprojected>> {
    let mut sorted = targets.to_vec();
    sorted.sort_by(|a, b| a.height_mm.total_cmp(&b.height_mm));
    let mut out: Vec<Vec<Reprojected>> = Vec::new();
    for t in sorted {
        match out.last_mut() {
            Some(layer) if t.height_mm - layer[0].height_mm < LAYER_GAP_MM => layer.push(t),
            _ => out.push(vec![t]),
        }
    }
    out
}

/// The arrows' scale: the largest power-of-ten multiple of 1, 2 or 5 that
/// keeps the longest residual within [`LONGEST_ARROW`] of the sensor's
/// width.
pub fn arrow_scale(targets: &[Reprojected], width_px: f64) -> f64 {
    let longest = targets
        .iter()
        .map(|t| (t.measured[0] - t.predicted[0]).hypot(t.measured[1] - t.predicted[1]))
        .fold(0.0, f64::max);
    if !(longest > 0.0 && longest.is_finite()) {
        return 1.0;
    }
    let s = LONGEST_ARROW * width_px / longest;
    let decade = 10f64.powf(s.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|&v| v <= s)
        .unwrap_or(decade)
}

/// Writes the picture to `path` (PNG), one panel per height.
///
/// # Errors
/// [`PlotError`] naming the file.
pub fn targets_on_sensor_png(
    cal: &Calibration,
    input: &CalibrationInput,
    path: &Path,
) -> Result<(), PlotError> {
    register_font()?;
    let targets = reprojected(cal, input);
    if targets.is_empty() {
        return Err(PlotError::Empty {
            argument: "targets",
        });
    }
    let cam = &cal.station.camera;
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let scale = arrow_scale(&targets, w);
    let layers = layers(&targets);
    let panel_h = (f64::from(PANEL_PX) * h / w).round() as u32 + 130;
    let size = (PANEL_PX * layers.len() as u32, panel_h);
    let fail = |e: &dyn std::fmt::Display| PlotError::Draw {
        path: path.to_path_buf(),
        source: e.to_string().into(),
    };
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(&e))?;
    for (area, layer) in root.split_evenly((1, layers.len())).iter().zip(&layers) {
        panel(area, layer, (w, h), scale).map_err(|e| fail(&e))?;
    }
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

/// The plotted rows run to this multiple of the sensor's height: the band
/// below the sensor holds the legend (the planned targets reach the
/// sensor's corners, `make::target_layout`).
const LEGEND_BAND: f64 = 1.35;

type Drawn<'a> = Result<(), DrawingAreaErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

fn panel<'a>(
    area: &DrawingArea<BitMapBackend<'a>, Shift>,
    layer: &[Reprojected],
    (w, h): (f64, f64),
    scale: f64,
) -> Drawn<'a> {
    let z = layer.iter().map(|t| t.height_mm).sum::<f64>() / layer.len() as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("targets at z = {z:.1} mm ({})", layer.len()),
            (FAMILY, 20),
        )
        .margin(12)
        .x_label_area_size(55)
        .y_label_area_size(60)
        // Rows run down the sensor, as in its frames; a band below the
        // sensor holds the legend, clear of the targets at its edges.
        .build_cartesian_2d(0.0..w, LEGEND_BAND * h..0.0)?;
    chart
        .configure_mesh()
        .max_light_lines(0)
        .x_desc(format!("column, px (residual arrows × {scale})"))
        .y_desc("row, px")
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 15))
        .draw()?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(0.0, 0.0), (w, h)],
            BLACK.mix(0.5).stroke_width(1),
        )))?
        .label("sensor")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 16, y + 5)], BLACK.mix(0.5)));
    chart
        .draw_series(layer.iter().map(|t| {
            PathElement::new(
                vec![
                    (t.predicted[0], t.predicted[1]),
                    (
                        t.predicted[0] + scale * (t.measured[0] - t.predicted[0]),
                        t.predicted[1] + scale * (t.measured[1] - t.predicted[1]),
                    ),
                ],
                BLACK.stroke_width(2),
            )
        }))?
        .label(format!("residual × {scale}"))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.stroke_width(2)));
    chart
        .draw_series(
            layer
                .iter()
                .map(|t| Cross::new((t.predicted[0], t.predicted[1]), 5, RED.stroke_width(2))),
        )?
        .label("calibrated projection")
        .legend(|(x, y)| Cross::new((x + 8, y), 5, RED.stroke_width(2)));
    chart
        .draw_series(
            layer
                .iter()
                .map(|t| Circle::new((t.measured[0], t.measured[1]), 5, BLUE.stroke_width(2))),
        )?
        .label("measured centroid")
        .legend(|(x, y)| Circle::new((x + 8, y), 5, BLUE.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FAMILY, 13))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(z: f64, m: [f64; 2], p: [f64; 2]) -> Reprojected {
        Reprojected {
            height_mm: z,
            measured: m,
            predicted: p,
        }
    }

    #[test]
    fn layers_and_scale() {
        let ts = [
            t(60.001, [10.0, 10.0], [10.03, 10.04]),
            t(0.0, [1.0, 1.0], [1.0, 1.0]),
            t(59.999, [5.0, 5.0], [5.0, 5.0]),
            t(120.0, [2.0, 2.0], [2.0, 2.0]),
        ];
        let l = layers(&ts);
        assert_eq!(l.iter().map(Vec::len).collect::<Vec<_>>(), vec![1, 2, 1]);
        // Longest residual 0.05 px on a 1000 px sensor: 80 px allowed, so
        // ×1600 fits and the largest 1-2-5 value below it is 1000.
        assert_eq!(arrow_scale(&ts, 1000.0), 1000.0);
    }
}
