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

use super::canvas::{Canvas, Rgb, BLACK, WHITE};
use super::font::{draw_text, draw_text_up, text_height, text_width};
use super::lines_axis::{usable, Axis};
use super::strokes::{marker, segment, MARKERS};
use super::{draw_centred, label_top, PlotError, MARGIN, NO_DATA, TEXT_SCALE};

/// Most series one panel draws: one per colour and marker shape.
pub const MAX_SERIES: usize = 8;
/// Plot area of each panel, in pixels.
const PLOT_W: usize = 480;
const PLOT_H: usize = 360;
/// Tick mark length and the gap between mark and label.
const TICK: usize = 6;
const LABEL_GAP: usize = 6;
/// Most ticks per axis (x labels sit side by side, so fewer).
const MAX_X_TICKS: usize = 6;
const MAX_Y_TICKS: usize = 7;
/// Room right of the plot for half of the last x label.
const RIGHT_PAD: usize = 32;
/// Half the width of series lines, in pixels.
const LINE_HALF_WIDTH: f64 = 1.0;
/// Grid lines at the ticks.
const GRID: Rgb = [225, 225, 225];
/// Series colours: matplotlib's "tab10" (Tableau 10) without its grey,
/// which would read as grid.
const PALETTE: [Rgb; MAX_SERIES] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];
/// Legend: inset from the plot frame, inner padding, sample line length,
/// gap before the label, row pitch.
const LEGEND_INSET: usize = 8;
const LEGEND_PAD: usize = 6;
const LEGEND_SAMPLE: usize = 28;
const LEGEND_GAP: usize = 8;
const LEGEND_ROW: usize = 22;

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

/// Where one panel goes, in canvas pixels, and its axes.
#[derive(Debug, Clone)]
struct PanelGeom {
    left: usize,
    width: usize,
    plot_x: usize,
    plot_y: usize,
    x: Axis,
    y: Axis,
}

/// Height of every panel and so of the picture: title, plot, tick labels,
/// x axis name.
fn picture_height() -> usize {
    let th = text_height(TEXT_SCALE);
    plot_top() + PLOT_H + TICK + LABEL_GAP + th + 10 + th + MARGIN
}

/// First row of every plot area.
fn plot_top() -> usize {
    MARGIN + text_height(TEXT_SCALE) + 12
}

impl PanelGeom {
    fn new(panel: &Panel, left: usize) -> Self {
        // Only points that can be drawn set the ranges.
        let points = || {
            let all = panel.series.iter().flat_map(|s| s.points.iter());
            all.filter(|p| usable(p.0, panel.log_x) && usable(p.1, panel.log_y))
        };
        let x = Axis::new(points().map(|p| p.0), panel.log_x, MAX_X_TICKS);
        let y = Axis::new(points().map(|p| p.1), panel.log_y, MAX_Y_TICKS);
        let label_w = y.labels.iter().map(|l| text_width(l, TEXT_SCALE)).max();
        // Axis name (turned), a gap, the labels, the tick marks.
        let th = text_height(TEXT_SCALE);
        let plot_dx = MARGIN + th + 10 + label_w.unwrap_or(0) + LABEL_GAP + TICK;
        let width = (plot_dx + PLOT_W + RIGHT_PAD)
            .max(plot_dx + text_width(panel.title, TEXT_SCALE) / 2 + PLOT_W / 2 + MARGIN);
        Self {
            left,
            width,
            plot_x: left + plot_dx,
            plot_y: plot_top(),
            x,
            y,
        }
    }

    /// Canvas position of data point `p`, or `None` where it cannot be
    /// drawn (non-finite, or not positive on a log axis).
    fn to_px(&self, p: (f64, f64)) -> Option<(f64, f64)> {
        let (fx, fy) = (self.x.frac(p.0)?, self.y.frac(p.1)?);
        Some((
            self.plot_x as f64 + fx * (PLOT_W - 1) as f64,
            self.plot_y as f64 + (1.0 - fy) * (PLOT_H - 1) as f64,
        ))
    }

    fn right(&self) -> i64 {
        (self.plot_x + PLOT_W - 1) as i64
    }

    fn bottom(&self) -> i64 {
        (self.plot_y + PLOT_H - 1) as i64
    }
}

/// Draws `panels` side by side in one RGB8 PNG, each with a 480×360 plot
/// area: title, grid and ticks (1-2-5 steps, or powers of ten on log
/// axes), each series as a 2-pixel anti-aliased polyline in its own colour
/// with its own marker shape, and a legend in the plot corner it hides
/// least. Points that cannot be placed (NaN, infinite, or not positive on
/// a log axis) are skipped and break the line there; a series without any
/// still appears in the legend, and a panel without any reads "no data".
///
/// # Errors
/// [`PlotError::Empty`] if `panels` is empty, [`PlotError::TooMany`] if a
/// panel has more than [`MAX_SERIES`] series, [`PlotError::Io`] /
/// [`PlotError::Encode`] naming `path` if the file cannot be written.
pub fn line_plot_png(path: &Path, panels: &[Panel]) -> Result<(), PlotError> {
    render(panels)?.write_png(path)
}

/// The picture [`line_plot_png`] writes.
fn render(panels: &[Panel]) -> Result<Canvas, PlotError> {
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
    let geoms = layout(panels);
    let width = geoms.last().map_or(0, |g| g.left + g.width);
    let mut c = Canvas::new(width, picture_height(), WHITE);
    for (panel, g) in panels.iter().zip(&geoms) {
        draw_panel(&mut c, panel, g);
    }
    Ok(c)
}

/// Each panel's place, left to right.
fn layout(panels: &[Panel]) -> Vec<PanelGeom> {
    let mut left = 0;
    panels
        .iter()
        .map(|p| {
            let g = PanelGeom::new(p, left);
            left += g.width;
            g
        })
        .collect()
}

fn draw_panel(c: &mut Canvas, panel: &Panel, g: &PanelGeom) {
    let cx = (g.plot_x + PLOT_W / 2) as i64;
    draw_centred(c, cx, MARGIN as i64, panel.title, BLACK);
    draw_grid(c, g);
    let mut any = false;
    for (k, s) in panel.series.iter().enumerate() {
        any |= draw_series(c, g, s, k);
    }
    c.stroke_rect(
        g.plot_x as i64 - 1,
        g.plot_y as i64 - 1,
        PLOT_W + 2,
        PLOT_H + 2,
        BLACK,
    );
    draw_axis_names(c, g, panel);
    if !any {
        let cy = (g.plot_y + PLOT_H / 4) as i64;
        draw_centred(c, cx, label_top(cy), NO_DATA, BLACK);
    }
    if !panel.series.is_empty() {
        draw_legend(c, g, panel.series);
    }
}

/// Grid lines, tick marks and tick labels of both axes.
fn draw_grid(c: &mut Canvas, g: &PanelGeom) {
    let (x0, y0) = (g.plot_x as i64, g.plot_y as i64);
    for (&v, label) in g.y.ticks.iter().zip(&g.y.labels) {
        let Some((_, y)) = g.to_px((x_any(g), v)) else {
            continue;
        };
        let y = y.round() as i64;
        c.hline(x0, g.right(), y, GRID);
        c.hline(x0 - 1 - TICK as i64, x0 - 2, y, BLACK);
        let lx = x0 - 1 - (TICK + LABEL_GAP + text_width(label, TEXT_SCALE)) as i64;
        draw_text(c, lx, label_top(y), label, TEXT_SCALE, BLACK);
    }
    let below = g.bottom() + 2;
    for (&v, label) in g.x.ticks.iter().zip(&g.x.labels) {
        let Some((x, _)) = g.to_px((v, y_any(g))) else {
            continue;
        };
        let x = x.round() as i64;
        c.vline(x, y0, g.bottom(), GRID);
        c.vline(x, below, below + TICK as i64 - 1, BLACK);
        draw_centred(c, x, below + (TICK + LABEL_GAP) as i64, label, BLACK);
    }
}

/// A value placeable on the x axis (its first tick), to look up y rows.
fn x_any(g: &PanelGeom) -> f64 {
    g.x.ticks.first().copied().unwrap_or(1.0)
}

/// A value placeable on the y axis, to look up x columns.
fn y_any(g: &PanelGeom) -> f64 {
    g.y.ticks.first().copied().unwrap_or(1.0)
}

fn draw_axis_names(c: &mut Canvas, g: &PanelGeom, panel: &Panel) {
    let th = text_height(TEXT_SCALE) as i64;
    let name_y = g.bottom() + 2 + (TICK + LABEL_GAP) as i64 + th + 10;
    draw_centred(
        c,
        (g.plot_x + PLOT_W / 2) as i64,
        name_y,
        panel.x_label,
        BLACK,
    );
    let w = text_width(panel.y_label, TEXT_SCALE) as i64;
    let top = (g.plot_y + PLOT_H / 2) as i64 - w / 2;
    draw_text_up(
        c,
        (g.left + MARGIN) as i64,
        top,
        panel.y_label,
        TEXT_SCALE,
        BLACK,
    );
}

/// Series `k`'s line, broken at points that cannot be placed, then its
/// markers. Whether any point was drawn.
fn draw_series(c: &mut Canvas, g: &PanelGeom, s: &Series, k: usize) -> bool {
    let color = PALETTE[k % MAX_SERIES];
    let placed: Vec<Option<(f64, f64)>> = s.points.iter().map(|&p| g.to_px(p)).collect();
    for pair in placed.windows(2) {
        if let [Some(a), Some(b)] = pair {
            segment(c, *a, *b, LINE_HALF_WIDTH, color);
        }
    }
    for p in placed.iter().flatten() {
        marker(c, *p, MARKERS[k % MAX_SERIES], color);
    }
    placed.iter().any(Option::is_some)
}

/// Width and height of the legend box for `series`.
fn legend_size(series: &[Series]) -> (usize, usize) {
    let label_w = series.iter().map(|s| text_width(s.label, TEXT_SCALE)).max();
    let w = 2 * LEGEND_PAD + LEGEND_SAMPLE + LEGEND_GAP + label_w.unwrap_or(0);
    (w, 2 * LEGEND_PAD + series.len() * LEGEND_ROW - 4)
}

/// Data pixels (neither page nor grid) inside the `w`×`h` box at (`x`, `y`).
fn ink_under(c: &Canvas, x: i64, y: i64, w: usize, h: usize) -> usize {
    let xs = x.max(0) as usize..((x + w as i64).max(0) as usize).min(c.width());
    let ys = y.max(0) as usize..((y + h as i64).max(0) as usize).min(c.height());
    ys.flat_map(|row| xs.clone().map(move |col| (col, row)))
        .filter(|&(col, row)| !matches!(c.get(col, row), WHITE | GRID))
        .count()
}

/// The legend in the plot corner (top right, top left, bottom right,
/// bottom left, preferred in that order) where it covers the fewest data
/// pixels.
fn draw_legend(c: &mut Canvas, g: &PanelGeom, series: &[Series]) {
    let (w, h) = legend_size(series);
    let inset = LEGEND_INSET as i64;
    let (left, top) = (g.plot_x as i64 + inset, g.plot_y as i64 + inset);
    let right = g.right() - inset - w as i64 + 1;
    let bottom = g.bottom() - inset - h as i64 + 1;
    let corners = [(right, top), (left, top), (right, bottom), (left, bottom)];
    let (x, y) = corners
        .into_iter()
        .min_by_key(|&(x, y)| ink_under(c, x, y, w, h))
        .unwrap_or((right, top));
    c.fill_rect(x, y, w, h, WHITE);
    c.stroke_rect(x, y, w, h, [120, 120, 120]);
    for (k, s) in series.iter().enumerate() {
        let color = PALETTE[k % MAX_SERIES];
        let row = y + (LEGEND_PAD + k * LEGEND_ROW) as i64;
        let mid = (row + text_height(TEXT_SCALE) as i64 / 2 - 2) as f64;
        let x0 = (x + LEGEND_PAD as i64) as f64;
        let x1 = x0 + LEGEND_SAMPLE as f64;
        segment(c, (x0 + 1.0, mid), (x1 - 1.0, mid), LINE_HALF_WIDTH, color);
        marker(c, ((x0 + x1) / 2.0, mid), MARKERS[k % MAX_SERIES], color);
        let tx = x1 as i64 + LEGEND_GAP as i64;
        draw_text(c, tx, row, s.label, TEXT_SCALE, BLACK);
    }
}

#[cfg(test)]
#[path = "lines_tests.rs"]
mod tests;
