//! A bar chart of Zernike coefficients against Noll index j, with ±1σ
//! error bars.
//!
//! ```text
//!                      title
//!   coefficient  60 -+---------------------+
//!   (nm)             |  █                  |
//!                 0 -|--█--▄-----█---------|   zero line
//!                    |     █               |
//!               -40 -+---------------------+
//!                    5    10   15   20
//!                         Noll j
//! ```

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::font::{self, LABEL_PX, TICK_PX, TITLE_PX};
use super::output::{self, Drawn, Figure, Format, Rasters};
use super::{PlotError, NO_DATA};

/// Most coefficients one chart draws (Noll j up to about 1000 would be
/// radial order 44; our fits stop at 231 terms, order 20).
pub const MAX_BARS: usize = 1000;
/// The plot area is at least this wide; beyond ~93 bars it grows by
/// [`MIN_PITCH`] per bar.
const PLOT_MIN_W: u32 = 560;
/// Narrowest bar pitch in pixels.
const MIN_PITCH: u32 = 6;
/// Plot area height in pixels.
const PLOT_H: u32 = 360;
/// Blank border, and the label areas left of and below the plot.
const MARGIN: u32 = 16;
const Y_AXIS_W: u32 = 90;
const X_AXIS_H: u32 = 60;
/// Room right of the plot for half of the last x label.
const RIGHT_PAD: u32 = 24;
/// Pixels per x label, so that labels never touch.
const X_LABEL_PITCH: u32 = 40;
/// Each bar's width as a fraction of its pitch.
const BAR_FILL: f64 = 0.7;
/// Head room above and below the data, as a fraction of its span.
const PAD: f64 = 0.06;

/// Bars of positive and negative coefficients (the ends of the height
/// map's colour map, so that sign reads the same in both pictures).
pub(super) const POSITIVE: RGBColor = RGBColor(178, 24, 43);
pub(super) const NEGATIVE: RGBColor = RGBColor(33, 102, 172);
/// Horizontal grid lines at the y ticks.
const GRID: RGBColor = RGBColor(225, 225, 225);

/// The ±1σ half-width of bar `i` when it gets an error bar.
fn sigma(std: &[f64], i: usize) -> Option<f64> {
    std.get(i).copied().filter(|s| s.is_finite() && *s > 0.0)
}

/// Lowest and highest point to show: every finite bar with its error bar,
/// and zero. `None` if no value is finite.
fn data_range(values: &[f64], std: &[f64]) -> Option<(f64, f64)> {
    let mut range: Option<(f64, f64)> = None;
    for (i, &v) in values.iter().enumerate().filter(|(_, v)| v.is_finite()) {
        let s = sigma(std, i).unwrap_or(0.0);
        let (lo, hi) = range.unwrap_or((0.0, 0.0));
        range = Some((lo.min(v - s), hi.max(v + s)));
    }
    range
}

/// A validated chart, ready to draw.
struct Chart<'a> {
    values: &'a [f64],
    std: &'a [f64],
    first_index: usize,
    title: &'a str,
    /// The y axis, nm.
    y: (f64, f64),
    /// Whether any value is finite.
    any: bool,
    /// Plot area: left, top, width, height; and the picture's size.
    plot: (u32, u32, u32, u32),
    size: (u32, u32),
}

impl<'a> Chart<'a> {
    fn new(
        values: &'a [f64],
        std: &'a [f64],
        first_index: usize,
        title: &'a str,
    ) -> Result<Self, PlotError> {
        let n = values.len();
        if n == 0 {
            return Err(PlotError::Empty { argument: "values" });
        }
        if n > MAX_BARS {
            return Err(PlotError::TooMany {
                argument: "values",
                count: n,
                max: MAX_BARS,
            });
        }
        if !std.is_empty() && std.len() != n {
            return Err(PlotError::LengthMismatch {
                argument: "std",
                expected: n,
                found: std.len(),
            });
        }
        font::register()?;
        let range = data_range(values, std);
        let (lo, hi) = range.unwrap_or((-1.0, 1.0));
        let pad = PAD * (hi - lo).max(f64::MIN_POSITIVE);
        let plot_w = PLOT_MIN_W.max(MIN_PITCH * n as u32);
        let content_w = Y_AXIS_W + plot_w + RIGHT_PAD;
        let width = content_w.max(font::text_width(title, TITLE_PX)) + 2 * MARGIN;
        let top = MARGIN + TITLE_PX as u32 + 16;
        let left = (width - content_w) / 2 + Y_AXIS_W;
        Ok(Self {
            values,
            std,
            first_index,
            title,
            y: (lo - pad, hi + pad),
            any: range.is_some(),
            plot: (left, top, plot_w, PLOT_H),
            size: (width, top + PLOT_H + X_AXIS_H + MARGIN),
        })
    }

    /// The x axis: Noll j, each bar one unit wide about its index.
    fn x(&self) -> (f64, f64) {
        let j0 = self.first_index as f64;
        (j0 - 0.5, j0 + self.values.len() as f64 - 0.5)
    }

    /// Bars from zero to each finite value, then the zero line over their
    /// feet, then black ±1σ error bars (a cap at each end, a ring at the
    /// value).
    fn draw_bars<DB: DrawingBackend>(
        &self,
        chart: &mut ChartContext<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    ) -> Drawn<DB> {
        let j = |i: usize| (self.first_index + i) as f64;
        let finite = || {
            self.values
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
        };
        chart.draw_series(finite().map(|(i, &v)| {
            let color = if v >= 0.0 { POSITIVE } else { NEGATIVE };
            let half = BAR_FILL / 2.0;
            Rectangle::new([(j(i) - half, 0.0), (j(i) + half, v)], color.filled())
        }))?;
        let (x0, x1) = self.x();
        chart.draw_series(std::iter::once(PathElement::new(
            [(x0, 0.0), (x1, 0.0)],
            BLACK,
        )))?;
        let pitch = f64::from(self.plot.2) / self.values.len() as f64;
        let cap = ((pitch * BAR_FILL * 0.6).round() as u32).clamp(2, 8);
        chart.draw_series(finite().filter_map(|(i, &v)| {
            let s = sigma(self.std, i)?;
            Some(ErrorBar::new_vertical(j(i), v - s, v, v + s, BLACK, cap))
        }))?;
        Ok(())
    }
}

impl Figure for Chart<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, _: &Rasters) -> Drawn<DB> {
        let title = Text::new(
            self.title.to_string(),
            ((self.size.0 / 2) as i32, MARGIN as i32),
            font::text(TITLE_PX).pos(Pos::new(HPos::Center, VPos::Top)),
        );
        root.draw(&title)?;
        let (x, y, w, h) = self.plot;
        let area = root
            .clone()
            .shrink((x - Y_AXIS_W, y), (w + Y_AXIS_W, h + X_AXIS_H));
        let (x0, x1) = self.x();
        let mut chart = ChartBuilder::on(&area)
            .y_label_area_size(Y_AXIS_W)
            .x_label_area_size(X_AXIS_H)
            .build_cartesian_2d(x0..x1, self.y.0..self.y.1)?;
        let x_labels = self.values.len().min((w / X_LABEL_PITCH) as usize).max(1);
        let integer = |v: &f64| {
            let r = v.round();
            if (v - r).abs() < 1e-6 {
                format!("{r}")
            } else {
                String::new()
            }
        };
        chart
            .configure_mesh()
            .disable_x_mesh()
            .y_max_light_lines(0)
            .bold_line_style(GRID)
            .x_labels(x_labels)
            .y_labels(7)
            .label_style(font::text(TICK_PX))
            .axis_desc_style(font::text(LABEL_PX))
            .x_desc("Noll j")
            .y_desc("coefficient (nm)")
            .x_label_formatter(&integer)
            .y_label_formatter(&|v| font::tick_label(*v))
            .draw()?;
        self.draw_bars(&mut chart)?;
        let plot = chart.plotting_area().strip_coord_spec();
        let (pw, ph) = plot.dim_in_pixel();
        plot.draw(&Rectangle::new(
            [(0, 0), (pw as i32 - 1, ph as i32 - 1)],
            BLACK,
        ))?;
        if !self.any {
            let at = ((pw / 2) as i32, (ph / 4) as i32);
            let style = font::text(LABEL_PX).pos(Pos::new(HPos::Center, VPos::Center));
            plot.draw(&Text::new(NO_DATA, at, style))?;
        }
        Ok(())
    }
}

/// Draws Zernike coefficients `values` (nm) as bars at Noll indices
/// `first_index`, `first_index + 1`, …, with ±`std` (nm) error bars, a zero
/// line, y ticks on 1-2-5 steps over every bar and error bar, integer x
/// ticks no closer than 40 pixels, and the axis names "Noll j" and
/// "coefficient (nm)". Positive bars are red, negative blue. The plot area
/// is 560 pixels wide, or 6 per bar beyond 93 bars.
///
/// `std` holds one entry per value, or none at all for no error bars; a NaN,
/// zero or negative entry draws no error bar. A NaN value draws no bar; with
/// no finite value the chart reads "no data".
///
/// # Errors
/// [`PlotError::Empty`] if `values` is empty, [`PlotError::TooMany`] beyond
/// [`MAX_BARS`], [`PlotError::LengthMismatch`] if `std` is neither empty nor
/// as long as `values`, [`PlotError::Io`] / [`PlotError::Encode`] /
/// [`PlotError::Draw`] naming `path` if the picture cannot be written.
pub fn coefficient_chart_png(
    path: &Path,
    values: &[f64],
    std: &[f64],
    first_index: usize,
    title: &str,
) -> Result<(), PlotError> {
    output::write(
        path,
        Format::Png,
        &Chart::new(values, std, first_index, title)?,
    )
}

/// [`coefficient_chart_png`] as SVG.
///
/// # Errors
/// As [`coefficient_chart_png`].
pub fn coefficient_chart_svg(
    path: &Path,
    values: &[f64],
    std: &[f64],
    first_index: usize,
    title: &str,
) -> Result<(), PlotError> {
    output::write(
        path,
        Format::Svg,
        &Chart::new(values, std, first_index, title)?,
    )
}

#[cfg(test)]
#[path = "chart_tests.rs"]
mod tests;
