//! Line plots: panels side by side, each with its series as polylines with
//! markers, a legend, and linear or logarithmic axes.
//!
//! ```text
//!          title              title
//!   y  100 +-----------+  ... +-----------+
//!          |  ●-●  [leg]|     |           |
//!       10 |-■---■------|     |           |
//!          +-----------+      +-----------+
//!          1    10   100
//!             x label
//! ```

use std::path::Path;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::font::{self, LABEL_PX, TICK_PX, TITLE_PX};
use super::lines_axis::{legend_corner, usable, AxisRange};
use super::output::{self, Drawn, Figure, Format, Rasters};
use super::{PlotError, NO_DATA};

/// Most series one panel draws: one per colour and marker shape.
pub const MAX_SERIES: usize = 8;
/// Plot area of each panel, in pixels.
const PLOT_W: u32 = 480;
const PLOT_H: u32 = 360;
/// Blank border, and the label areas left of and below each plot.
const MARGIN: u32 = 16;
const Y_AXIS_W: u32 = 90;
const X_AXIS_H: u32 = 60;
/// Room right of each plot for half of the last x label.
const RIGHT_PAD: u32 = 32;
/// A panel's width when its title is not wider.
const PANEL_W: u32 = MARGIN + Y_AXIS_W + PLOT_W + RIGHT_PAD;
/// Series line width and marker size, pixels.
const LINE_W: u32 = 2;
const MARKER_R: i32 = 5;
/// Half the length of a legend's line sample.
const LEGEND_SAMPLE: i32 = 14;
/// Series colours: matplotlib's "tab10" (Tableau 10) without its grey,
/// which would read as grid.
pub(super) const PALETTE: [RGBColor; MAX_SERIES] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];
/// Grid lines at the ticks, and the legend's frame.
const GRID: RGBColor = RGBColor(225, 225, 225);
pub(super) const LEGEND_BORDER: RGBColor = RGBColor(120, 120, 120);

/// One line series: points (x, y), a legend label; drawn as a polyline with
/// markers.
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Points in drawing order, in the panel's axis units.
    pub points: &'a [(f64, f64)],
}

/// A panel: title, axis labels, log-scale flags, and its series.
#[derive(Debug, Clone, Copy)]
pub struct Panel<'a> {
    /// Written above the plot area.
    pub title: &'a str,
    /// Axis names, with their units.
    pub x_label: &'a str,
    /// See `x_label`.
    pub y_label: &'a str,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// At most [`MAX_SERIES`] series.
    pub series: &'a [Series<'a>],
}

impl Panel<'_> {
    /// The points that can be drawn (finite, and positive on a log axis).
    fn usable_points(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        let all = self.series.iter().flat_map(|s| s.points.iter().copied());
        all.filter(|p| usable(p.0, self.log_x) && usable(p.1, self.log_y))
    }
}

/// Where one panel goes: its left edge and width, in picture pixels.
#[derive(Debug, Clone, PartialEq)]
struct Geom {
    left: u32,
    width: u32,
    x: AxisRange,
    y: AxisRange,
}

impl Geom {
    /// The plot area's left edge, in picture pixels.
    fn plot_x(&self) -> u32 {
        self.left + MARGIN + (self.width - PANEL_W) / 2 + Y_AXIS_W
    }
}

/// The first row of every plot area.
fn plot_top() -> u32 {
    MARGIN + TITLE_PX as u32 + 14
}

/// Each panel's place, left to right.
fn layout(panels: &[Panel]) -> Vec<Geom> {
    let mut left = 0;
    panels
        .iter()
        .map(|p| {
            let x = AxisRange::new(p.usable_points().map(|q| q.0), p.log_x);
            let y = AxisRange::new(p.usable_points().map(|q| q.1), p.log_y);
            let width = PANEL_W.max(font::text_width(p.title, TITLE_PX) + 2 * MARGIN);
            let g = Geom { left, width, x, y };
            left += width;
            g
        })
        .collect()
}

/// A validated plot, ready to draw.
struct Plot<'a> {
    panels: &'a [Panel<'a>],
    geoms: Vec<Geom>,
}

impl<'a> Plot<'a> {
    fn new(panels: &'a [Panel<'a>]) -> Result<Self, PlotError> {
        if panels.is_empty() {
            return Err(PlotError::Empty { argument: "panels" });
        }
        if let Some(p) = panels.iter().find(|p| p.series.len() > MAX_SERIES) {
            return Err(PlotError::TooMany {
                argument: "series",
                count: p.series.len(),
                max: MAX_SERIES,
            });
        }
        font::register()?;
        Ok(Self {
            geoms: layout(panels),
            panels,
        })
    }
}

impl Figure for Plot<'_> {
    fn size(&self) -> (u32, u32) {
        let g = self.geoms.last().expect("at least one panel");
        (g.left + g.width, plot_top() + PLOT_H + X_AXIS_H + MARGIN)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, _: &Rasters) -> Drawn<DB> {
        for (panel, g) in self.panels.iter().zip(&self.geoms) {
            let title = Text::new(
                panel.title.to_string(),
                ((g.plot_x() + PLOT_W / 2) as i32, MARGIN as i32),
                font::text(TITLE_PX).pos(Pos::new(HPos::Center, VPos::Top)),
            );
            root.draw(&title)?;
            let at = (g.plot_x() - Y_AXIS_W, plot_top());
            let area = root
                .clone()
                .shrink(at, (Y_AXIS_W + PLOT_W, PLOT_H + X_AXIS_H));
            let (x, y) = (g.x.span(), g.y.span());
            match (panel.log_x, panel.log_y) {
                (false, false) => draw_panel(&area, panel, g, x, y),
                (true, false) => draw_panel(&area, panel, g, x.log_scale(), y),
                (false, true) => draw_panel(&area, panel, g, x, y.log_scale()),
                (true, true) => draw_panel(&area, panel, g, x.log_scale(), y.log_scale()),
            }?;
        }
        Ok(())
    }
}

/// One panel on `area` (its label areas and plot), with axes `x` and `y`.
/// (About 90 lines: one plotters builder chain — mesh, series with their
/// broken segments and markers, legend placement — that reads in order.)
fn draw_panel<DB, X, Y>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    g: &Geom,
    x: X,
    y: Y,
) -> Drawn<DB>
where
    DB: DrawingBackend,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .y_label_area_size(Y_AXIS_W)
        .x_label_area_size(X_AXIS_H)
        .build_cartesian_2d(x, y)?;
    let x_label = |v: &f64| g.x.label(*v);
    let y_label = |v: &f64| g.y.label(*v);
    chart
        .configure_mesh()
        .bold_line_style(GRID)
        .light_line_style(WHITE.mix(0.0))
        .x_labels(6)
        .y_labels(7)
        .label_style(font::text(TICK_PX))
        .axis_desc_style(font::text(LABEL_PX))
        .x_desc(panel.x_label)
        .y_desc(panel.y_label)
        .x_label_formatter(&x_label)
        .y_label_formatter(&y_label)
        .draw()?;
    let usable_point = |p: &&(f64, f64)| usable(p.0, panel.log_x) && usable(p.1, panel.log_y);
    for (k, s) in panel.series.iter().enumerate() {
        let color = PALETTE[k % MAX_SERIES];
        let line = color.stroke_width(LINE_W);
        for run in s.points.split(|p| !usable_point(&p)) {
            chart.draw_series(std::iter::once(PathElement::new(run.to_vec(), line)))?;
        }
        let points = s.points.iter().filter(usable_point);
        chart
            .draw_series(points.map(|&p| {
                let (fill, outline) = marker(k, color);
                EmptyElement::at(p) + fill + outline
            }))?
            .label(s.label)
            .legend(move |(x, y)| {
                let (fill, outline) = marker(k, color);
                let sample = PathElement::new([(-LEGEND_SAMPLE, 0), (LEGEND_SAMPLE, 0)], line);
                EmptyElement::at((x + LEGEND_SAMPLE, y)) + sample + fill + outline
            });
    }
    let plot = chart.plotting_area().strip_coord_spec();
    let (pw, ph) = plot.dim_in_pixel();
    plot.draw(&Rectangle::new(
        [(0, 0), (pw as i32 - 1, ph as i32 - 1)],
        BLACK,
    ))?;
    if panel.usable_points().next().is_none() {
        let style = font::text(LABEL_PX).pos(Pos::new(HPos::Center, VPos::Center));
        plot.draw(&Text::new(
            NO_DATA,
            ((pw / 2) as i32, (ph / 4) as i32),
            style,
        ))?;
    }
    if !panel.series.is_empty() {
        let polylines: Vec<Vec<(f64, f64)>> = panel
            .series
            .iter()
            .map(|s| {
                s.points
                    .iter()
                    .map(|&(px, py)| (g.x.frac(px), g.y.frac(py)))
                    .collect()
            })
            .collect();
        chart
            .configure_series_labels()
            .position(legend_corner(&polylines))
            .margin(8)
            .legend_area_size(2 * LEGEND_SAMPLE + 8)
            .label_font(font::text(LABEL_PX))
            .background_style(WHITE)
            .border_style(LEGEND_BORDER)
            .draw()?;
    }
    Ok(())
}

/// A pixel offset.
type Px = (i32, i32);

/// Series `k`'s marker, centred on (0, 0) in pixels: a disc, square,
/// triangle or diamond, filled for the first four series and outlined for
/// the next four, in the series' colour. As a filled polygon (transparent
/// for outlines) and its outline, so that every shape has one type.
fn marker(k: usize, color: RGBColor) -> (Polygon<Px>, PathElement<Px>) {
    let r = MARKER_R;
    let rf = f64::from(r);
    let corners: Vec<Px> = match k % 4 {
        0 => (0..16)
            .map(|i| {
                let a = f64::from(i) * std::f64::consts::PI / 8.0;
                ((rf * a.cos()).round() as i32, (rf * a.sin()).round() as i32)
            })
            .collect(),
        1 => vec![
            (-r + 1, -r + 1),
            (r - 1, -r + 1),
            (r - 1, r - 1),
            (-r + 1, r - 1),
        ],
        2 => vec![(0, -r), (r, r - 1), (-r, r - 1)],
        _ => vec![(0, -r), (r, 0), (0, r), (-r, 0)],
    };
    let fill = if k % MAX_SERIES < 4 {
        color.filled()
    } else {
        TRANSPARENT.filled()
    };
    let mut outline = corners.clone();
    outline.push(corners[0]);
    (
        Polygon::new(corners, fill),
        PathElement::new(outline, color.stroke_width(2)),
    )
}

/// Draws `panels` side by side in one PNG, each with a 480×360 plot area:
/// title, grid and ticks (1-2-5 steps, or powers of ten on log axes), each
/// series as a 2-pixel polyline in its own colour with its own marker
/// shape, and a legend in the plot corner it hides least. Points that
/// cannot be placed (NaN, infinite, or not positive on a log axis) are
/// skipped and break the line there; a series without any still appears in
/// the legend, and a panel without any reads "no data".
///
/// # Errors
/// [`PlotError::Empty`] if `panels` is empty, [`PlotError::TooMany`] if a
/// panel has more than [`MAX_SERIES`] series, [`PlotError::Io`] /
/// [`PlotError::Encode`] / [`PlotError::Draw`] naming `path` if the picture
/// cannot be written.
pub fn line_plot_png(path: &Path, panels: &[Panel]) -> Result<(), PlotError> {
    output::write(path, Format::Png, &Plot::new(panels)?)
}

/// [`line_plot_png`] as SVG.
///
/// # Errors
/// As [`line_plot_png`].
pub fn line_plot_svg(path: &Path, panels: &[Panel]) -> Result<(), PlotError> {
    output::write(path, Format::Svg, &Plot::new(panels)?)
}

#[cfg(test)]
#[path = "lines_tests.rs"]
mod tests;
