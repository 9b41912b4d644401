//! A height map with a colour bar.
//!
//! ```text
//!            title
//!                          unit
//!   +-----------------+   +--+-
//!   |                 |   |  |- 60
//!   |   map (nearest  |   |  |- 40
//!   |   neighbour,    |   |  |   ...
//!   |   ≥ 400 px)     |   |  |- -60
//!   +-----------------+   +--+-
//! ```

use std::path::Path;

use super::canvas::{Canvas, Rgb, BLACK, WHITE};
use super::colormap::diverging;
use super::font::{text_height, text_width};
use super::ticks::{covering_ticks, Ticks};
use super::{draw_centred, label_top, max_abs, PlotError, MARGIN, NO_DATA, TEXT_SCALE};

/// The map's longer side is drawn at least this many pixels long (by an
/// integer zoom) ...
const MAP_MIN: usize = 400;
/// ... and at most this many (by nearest-neighbour subsampling).
const MAP_MAX: usize = 800;
/// Colour bar width and its gap from the map, in pixels.
const BAR_W: usize = 24;
const BAR_GAP: usize = 24;
/// The bar is at least this tall, so that its tick labels never touch.
const BAR_MIN_H: usize = 200;
/// Tick mark length and the gap between mark and label.
const TICK: usize = 6;
const LABEL_GAP: usize = 6;
/// Most ticks on the bar; the symmetric range then gets 5 to 7.
const MAX_TICKS: usize = 7;

/// Where everything goes, in canvas pixels.
#[derive(Debug, Clone, PartialEq)]
struct Layout {
    width: usize,
    height: usize,
    title_y: usize,
    map_x: usize,
    map_y: usize,
    map_w: usize,
    map_h: usize,
    bar_x: usize,
    bar_y: usize,
    bar_h: usize,
}

/// The drawn size of a `w`×`h` map: integer zoom up to [`MAP_MIN`] on the
/// longer side, or down to [`MAP_MAX`].
fn display_size(w: usize, h: usize) -> (usize, usize) {
    let long = w.max(h);
    let target = if long < MAP_MIN {
        long * MAP_MIN.div_ceil(long)
    } else {
        long.min(MAP_MAX)
    };
    let f = target as f64 / long as f64;
    let side = |n: usize| ((n as f64 * f).round() as usize).max(1);
    (side(w), side(h))
}

fn layout(w: usize, h: usize, title: &str, unit: &str, labels: &[String]) -> Layout {
    let th = text_height(TEXT_SCALE);
    let (map_w, map_h) = display_size(w, h);
    let bar_h = map_h.max(BAR_MIN_H);
    let label_w = labels
        .iter()
        .map(|l| text_width(l, TEXT_SCALE))
        .max()
        .unwrap_or(0);
    let right = (TICK + LABEL_GAP + label_w).max(text_width(unit, TEXT_SCALE) / 2);
    let content_w = map_w + BAR_GAP + BAR_W + right;
    let width = content_w.max(text_width(title, TEXT_SCALE)) + 2 * MARGIN;
    let title_y = MARGIN;
    // Title, a gap, the unit above the bar, a gap.
    let top = title_y + th + 12 + th + 8;
    let map_x = (width - content_w) / 2;
    Layout {
        width,
        // Half a label hangs below the lowest tick.
        height: top + bar_h.max(map_h) + th / 2 + MARGIN,
        title_y,
        map_x,
        map_y: top,
        map_w,
        map_h,
        bar_x: map_x + map_w + BAR_GAP,
        bar_y: top,
        bar_h,
    }
}

/// Colour of height `v` on a bar from `ticks.lo()` to `ticks.hi()`.
fn color_of(v: f64, ticks: &Ticks) -> Rgb {
    diverging((v - ticks.lo()) / (ticks.hi() - ticks.lo()))
}

/// Draws the map, nearest source pixel per drawn pixel.
fn draw_map(c: &mut Canvas, l: &Layout, values: &[f64], w: usize, h: usize, ticks: &Ticks) {
    for dy in 0..l.map_h {
        let row = (dy * h / l.map_h).min(h - 1);
        for dx in 0..l.map_w {
            let col = (dx * w / l.map_w).min(w - 1);
            let v = values[row * w + col];
            // Infinities count as outside, like NaN.
            let v = if v.is_finite() { v } else { f64::NAN };
            c.set(
                (l.map_x + dx) as i64,
                (l.map_y + dy) as i64,
                color_of(v, ticks),
            );
        }
    }
}

/// Row of the bar showing value `v`.
fn bar_row(l: &Layout, ticks: &Ticks, v: f64) -> i64 {
    let t = (ticks.hi() - v) / (ticks.hi() - ticks.lo());
    l.bar_y as i64 + (t * (l.bar_h - 1) as f64).round() as i64
}

/// Draws the colour bar (top row the highest tick's colour, bottom row the
/// lowest's), its frame, ticks, labels and the unit above it.
fn draw_bar(c: &mut Canvas, l: &Layout, ticks: &Ticks, labels: &[String], unit: &str) {
    for r in 0..l.bar_h {
        let t = 1.0 - r as f64 / (l.bar_h - 1) as f64;
        c.fill_rect(l.bar_x as i64, (l.bar_y + r) as i64, BAR_W, 1, diverging(t));
    }
    let (x, y) = (l.bar_x as i64 - 1, l.bar_y as i64 - 1);
    c.stroke_rect(x, y, BAR_W + 2, l.bar_h + 2, BLACK);
    let right = (l.bar_x + BAR_W) as i64;
    for (&v, label) in ticks.values.iter().zip(labels) {
        let y = bar_row(l, ticks, v);
        c.hline(right, right + TICK as i64 - 1, y, BLACK);
        let lx = right + (TICK + LABEL_GAP) as i64;
        super::font::draw_text(c, lx, label_top(y), label, TEXT_SCALE, BLACK);
    }
    let uy = l.bar_y as i64 - 8 - text_height(TEXT_SCALE) as i64;
    draw_centred(c, (l.bar_x + BAR_W / 2) as i64, uy, unit, BLACK);
}

/// Draws the height map `values` (row-major, `width`×`height`, row 0 at the
/// top; NaN or infinite = outside the aperture, drawn grey) on the diverging
/// blue–white–red map of [`super::colormap`], symmetric about zero with
/// limits ±max|value| rounded up to a nice tick. A colour bar with 5 to 7
/// labelled ticks and `unit` stands at the right, `title` above. The map is
/// zoomed (nearest neighbour) to at least 400 pixels on its longer side,
/// or subsampled to at most 800. With no finite value the picture is drawn
/// with limits ±1 and "no data" written across the map.
///
/// # Errors
/// [`PlotError::Empty`] if `width` or `height` is zero,
/// [`PlotError::LengthMismatch`] if `values` does not hold
/// `width`×`height` entries, [`PlotError::Io`] / [`PlotError::Encode`]
/// naming `path` if the file cannot be written.
pub fn height_map_png(
    path: &Path,
    values: &[f64],
    width: usize,
    height: usize,
    title: &str,
    unit: &str,
) -> Result<(), PlotError> {
    render(values, width, height, title, unit)?.write_png(path)
}

/// The picture [`height_map_png`] writes.
fn render(
    values: &[f64],
    width: usize,
    height: usize,
    title: &str,
    unit: &str,
) -> Result<Canvas, PlotError> {
    if width == 0 || height == 0 {
        return Err(PlotError::Empty { argument: "values" });
    }
    let expected = width.saturating_mul(height);
    if values.len() != expected {
        return Err(PlotError::LengthMismatch {
            argument: "values",
            expected,
            found: values.len(),
        });
    }
    let limit = max_abs(values.iter().copied());
    let m = limit.unwrap_or(1.0);
    let ticks = covering_ticks(-m, m, MAX_TICKS);
    let labels: Vec<String> = ticks.values.iter().map(|&v| ticks.step.label(v)).collect();
    let l = layout(width, height, title, unit, &labels);
    let mut c = Canvas::new(l.width, l.height, WHITE);
    draw_centred(&mut c, (l.width / 2) as i64, l.title_y as i64, title, BLACK);
    draw_map(&mut c, &l, values, width, height, &ticks);
    draw_bar(&mut c, &l, &ticks, &labels, unit);
    if limit.is_none() {
        let (cx, cy) = (l.map_x + l.map_w / 2, l.map_y + l.map_h / 2);
        draw_centred(&mut c, cx as i64, label_top(cy as i64), NO_DATA, BLACK);
    }
    Ok(c)
}

#[cfg(test)]
#[path = "height_map_tests.rs"]
mod tests;
