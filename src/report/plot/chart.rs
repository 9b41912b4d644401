//! A bar chart of Zernike coefficients against Noll index, with ±1σ error
//! bars.
//!
//! ```text
//!                 title
//!  c    60 -+---------------------+
//!  o        |  █                  |
//!  e     0 -|--█--▄-----█---------|   zero line
//!  f        |     █               |
//!  .   -40 -+---------------------+
//!           5    10   15   20
//!                Noll j
//! ```

use std::path::Path;

use super::canvas::{Canvas, Rgb, BLACK, WHITE};
use super::font::{draw_text, draw_text_up, text_height, text_width};
use super::ticks::{covering_ticks, Ticks};
use super::{draw_centred, label_top, PlotError, MARGIN, NO_DATA, TEXT_SCALE};

/// Most coefficients one chart draws (Noll j up to about 1000 would be
/// radial order 44; our fits stop at 231 terms, order 20).
pub const MAX_BARS: usize = 1000;
/// The plot area is at least this wide; beyond ~93 bars it grows by
/// [`MIN_PITCH`] per bar.
const PLOT_MIN_W: usize = 560;
/// Narrowest bar pitch in pixels: a 4-pixel bar and a 2-pixel gap.
const MIN_PITCH: usize = 6;
/// Plot area height in pixels.
const PLOT_H: usize = 360;
/// Tick mark length and the gap between mark and label.
const TICK: usize = 6;
const LABEL_GAP: usize = 6;
/// Most ticks on the y axis.
const MAX_TICKS: usize = 7;

/// Bars of positive and negative coefficients (the ends of the height
/// map's colour map, so that sign reads the same in both pictures).
pub(super) const POSITIVE: Rgb = [178, 24, 43];
pub(super) const NEGATIVE: Rgb = [33, 102, 172];
/// Horizontal grid lines at the y ticks.
const GRID: Rgb = [225, 225, 225];

/// Where everything goes, in canvas pixels.
#[derive(Debug, Clone, PartialEq)]
struct Layout {
    width: usize,
    height: usize,
    title_y: usize,
    plot_x: usize,
    plot_y: usize,
    plot_w: usize,
    pitch: usize,
    bar_w: usize,
}

impl Layout {
    fn new(n: usize, title: &str, y_labels: &[String]) -> Self {
        let th = text_height(TEXT_SCALE);
        let pitch = (PLOT_MIN_W / n).max(MIN_PITCH);
        let label_w = y_labels
            .iter()
            .map(|l| text_width(l, TEXT_SCALE))
            .max()
            .unwrap_or(0);
        // Axis name (turned), a gap, the labels, the tick marks.
        let plot_x = MARGIN + th + 10 + label_w + LABEL_GAP + TICK;
        let plot_w = pitch * n;
        // Room right of the plot for half of the last x label.
        let right = plot_x + plot_w + 24 + MARGIN;
        let width = right.max(text_width(title, TEXT_SCALE) + 2 * MARGIN);
        let title_y = MARGIN;
        let plot_y = title_y + th + 16;
        // Tick marks, x labels, a gap, the axis name.
        let height = plot_y + PLOT_H + TICK + LABEL_GAP + th + 10 + th + MARGIN;
        Self {
            width,
            height,
            title_y,
            plot_x,
            plot_y,
            plot_w,
            pitch,
            bar_w: (pitch * 2 / 3).max(1),
        }
    }

    /// Row of value `v` on the y axis.
    fn row(&self, ticks: &Ticks, v: f64) -> i64 {
        let t = (ticks.hi() - v) / (ticks.hi() - ticks.lo());
        self.plot_y as i64 + (t * (PLOT_H - 1) as f64).round() as i64
    }

    /// First column of bar `i`.
    fn bar_x(&self, i: usize) -> i64 {
        (self.plot_x + i * self.pitch + (self.pitch - self.bar_w) / 2) as i64
    }

    /// Centre column of bar `i`.
    fn bar_centre(&self, i: usize) -> i64 {
        self.bar_x(i) + (self.bar_w / 2) as i64
    }
}

/// Labelled x ticks every this many Noll indices for `n` bars.
fn x_tick_every(n: usize) -> usize {
    match n {
        0..=12 => 1,
        13..=60 => 5,
        _ => 10,
    }
}

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

/// Grid, y ticks and labels, and the frame.
fn draw_axes(c: &mut Canvas, l: &Layout, ticks: &Ticks, labels: &[String]) {
    let (x0, x1) = (l.plot_x as i64, (l.plot_x + l.plot_w - 1) as i64);
    for (&v, label) in ticks.values.iter().zip(labels) {
        let y = l.row(ticks, v);
        c.hline(x0, x1, y, GRID);
        c.hline(x0 - TICK as i64, x0 - 1, y, BLACK);
        let lx = x0 - (TICK + LABEL_GAP + text_width(label, TEXT_SCALE)) as i64;
        draw_text(c, lx, label_top(y), label, TEXT_SCALE, BLACK);
    }
    c.stroke_rect(x0 - 1, l.plot_y as i64 - 1, l.plot_w + 2, PLOT_H + 2, BLACK);
}

/// X ticks and labels at multiples of [`x_tick_every`], and both axis names.
fn draw_x_axis(c: &mut Canvas, l: &Layout, n: usize, first_index: usize) {
    let every = x_tick_every(n);
    let below = (l.plot_y + PLOT_H + 1) as i64;
    for i in (0..n).filter(|i| (first_index + i) % every == 0) {
        let x = l.bar_centre(i);
        c.vline(x, below, below + TICK as i64 - 1, BLACK);
        let label = (first_index + i).to_string();
        draw_centred(c, x, below + (TICK + LABEL_GAP) as i64, &label, BLACK);
    }
    let th = text_height(TEXT_SCALE) as i64;
    let name_y = below + (TICK + LABEL_GAP) as i64 + th + 10;
    draw_centred(c, (l.plot_x + l.plot_w / 2) as i64, name_y, "Noll j", BLACK);
    let name = "coefficient (nm)";
    let name_top = (l.plot_y + PLOT_H / 2) as i64 - text_width(name, TEXT_SCALE) as i64 / 2;
    draw_text_up(c, MARGIN as i64, name_top, name, TEXT_SCALE, BLACK);
}

/// Bars from zero to each finite value, the zero line over their feet, then
/// black error bars with caps.
fn draw_bars(c: &mut Canvas, l: &Layout, ticks: &Ticks, values: &[f64], std: &[f64]) {
    let zero = l.row(ticks, 0.0);
    for (i, &v) in values.iter().enumerate().filter(|(_, v)| v.is_finite()) {
        let y = l.row(ticks, v);
        let color = if v >= 0.0 { POSITIVE } else { NEGATIVE };
        let (top, bottom) = (y.min(zero), y.max(zero));
        c.fill_rect(l.bar_x(i), top, l.bar_w, (bottom - top + 1) as usize, color);
    }
    let x1 = (l.plot_x + l.plot_w - 1) as i64;
    c.hline(l.plot_x as i64, x1, zero, BLACK);
    let cap = (l.bar_w / 2).min(4) as i64;
    for (i, &v) in values.iter().enumerate().filter(|(_, v)| v.is_finite()) {
        if let Some(s) = sigma(std, i) {
            let (x, top, bottom) = (l.bar_centre(i), l.row(ticks, v + s), l.row(ticks, v - s));
            c.vline(x, top, bottom, BLACK);
            c.hline(x - cap, x + cap, top, BLACK);
            c.hline(x - cap, x + cap, bottom, BLACK);
        }
    }
}

/// Draws Zernike coefficients `values` (nm) as bars at Noll indices
/// `first_index`, `first_index + 1`, …, with ±`std` (nm) error bars, a zero
/// line, y ticks on 1-2-5 steps covering every bar and error bar, x ticks
/// every 1, 5 or 10 indices (up to 12, up to 60, more bars) and the axis
/// names "Noll j" and "coefficient (nm)". Positive bars are red, negative
/// blue. The plot area is 560 pixels wide, or 6 per bar beyond 93 bars.
///
/// `std` holds one entry per value, or none at all for no error bars; a NaN,
/// zero or negative entry draws no error bar. A NaN value draws no bar; with
/// no finite value the chart reads "no data".
///
/// # Errors
/// [`PlotError::Empty`] if `values` is empty, [`PlotError::TooMany`] beyond
/// [`MAX_BARS`], [`PlotError::LengthMismatch`] if `std` is neither empty nor
/// as long as `values`, [`PlotError::Io`] / [`PlotError::Encode`] naming
/// `path` if the file cannot be written.
pub fn coefficient_chart_png(
    path: &Path,
    values: &[f64],
    std: &[f64],
    first_index: usize,
    title: &str,
) -> Result<(), PlotError> {
    render(values, std, first_index, title)?.write_png(path)
}

/// The picture [`coefficient_chart_png`] writes.
fn render(
    values: &[f64],
    std: &[f64],
    first_index: usize,
    title: &str,
) -> Result<Canvas, PlotError> {
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
    let range = data_range(values, std);
    let (lo, hi) = range.unwrap_or((-1.0, 1.0));
    let ticks = covering_ticks(lo, hi, MAX_TICKS);
    let labels: Vec<String> = ticks.values.iter().map(|&v| ticks.step.label(v)).collect();
    let l = Layout::new(n, title, &labels);
    let mut c = Canvas::new(l.width, l.height, WHITE);
    draw_centred(&mut c, (l.width / 2) as i64, l.title_y as i64, title, BLACK);
    draw_axes(&mut c, &l, &ticks, &labels);
    draw_bars(&mut c, &l, &ticks, values, std);
    draw_x_axis(&mut c, &l, n, first_index);
    if range.is_none() {
        let (cx, cy) = (l.plot_x + l.plot_w / 2, l.plot_y + PLOT_H / 4);
        draw_centred(&mut c, cx as i64, label_top(cy as i64), NO_DATA, BLACK);
    }
    Ok(c)
}

#[cfg(test)]
#[path = "chart_tests.rs"]
mod tests;
