//! Report pictures as RGB8 PNG files, drawn in pure Rust with a built-in
//! bitmap font (no system fonts, no plotting library).
//!
//! - [`height_map_png`]: a surface height map (nm) on the diverging map of
//!   [`colormap`], with a colour bar and a title.
//! - [`coefficient_chart_png`]: Zernike coefficients (nm) against Noll index
//!   as bars with ±1σ error bars.
//! - [`line_plot_png`]: panels of line series side by side, on linear or
//!   logarithmic axes, with markers and legends.
//! - [`nice_ticks`]: the 1-2-5 axis ticks they use.
//!
//! Pictures follow screen convention: pixel (0, 0) at the top left, rows
//! downwards; height-map row 0 is drawn at the top. Data that leave nothing
//! to draw (every value NaN) still give a picture, with "no data" written on
//! it, so a report never lacks a figure; wrong lengths and empty inputs are
//! errors.

pub mod canvas;
mod chart;
pub mod colormap;
pub mod font;
mod height_map;
mod lines;
mod lines_axis;
mod strokes;
mod ticks;

use std::path::PathBuf;

pub use chart::{coefficient_chart_png, MAX_BARS};
pub use height_map::height_map_png;
pub use lines::{line_plot_png, Panel, Series, MAX_SERIES};
pub use ticks::nice_ticks;

/// What went wrong drawing a picture.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The picture file could not be created.
    #[error("{path}: cannot create the picture: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The PNG encoder failed while writing.
    #[error("{path}: cannot write the PNG: {source}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: png::EncodingError,
    },
    /// An input slice's length disagrees with the others.
    #[error("`{argument}` has {found} entries where {expected} were expected")]
    LengthMismatch {
        /// The argument's name.
        argument: &'static str,
        /// The length the other arguments imply.
        expected: usize,
        /// Its actual length.
        found: usize,
    },
    /// Nothing to draw: an empty slice or a zero dimension.
    #[error("`{argument}` is empty: nothing to draw")]
    Empty {
        /// The argument's name.
        argument: &'static str,
    },
    /// More entries than a legible picture can hold.
    #[error("`{argument}` has {count} entries, more than the {max} a picture can show")]
    TooMany {
        /// The argument's name.
        argument: &'static str,
        /// Its length.
        count: usize,
        /// The most allowed.
        max: usize,
    },
}

/// Font scale of all text: each font pixel is a 2×2 square.
const TEXT_SCALE: usize = 2;
/// Blank border around every picture, in pixels.
const MARGIN: usize = 16;
/// Written across a plot area when no value is finite.
const NO_DATA: &str = "no data";

/// The largest magnitude among the finite `values`, or `None` if none is
/// finite.
fn max_abs(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .map(f64::abs)
        .reduce(f64::max)
}

/// Draws `text` centred horizontally on `cx` with its top at `y`.
fn draw_centred(canvas: &mut canvas::Canvas, cx: i64, y: i64, text: &str, color: canvas::Rgb) {
    let w = font::text_width(text, TEXT_SCALE) as i64;
    font::draw_text(canvas, cx - w / 2, y, text, TEXT_SCALE, color);
}

/// Where a tick label's top goes so that its capitals centre on row `y`.
fn label_top(y: i64) -> i64 {
    // Capitals occupy font rows 0..7; their middle is row 3.5.
    y - (7 * TEXT_SCALE / 2) as i64
}
