//! Pictures, drawn with `plotters` as PNG or SVG files, with text in an
//! embedded DejaVu Sans (no system fonts needed). The plotting kernel of
//! `report`, `budget`, `compare` and `calibrate`: it uses no other module
//! of mfd.
//!
//! - [`height_map_png`] / [`height_map_svg`] / [`height_map`]: a surface
//!   height map (nm) on a diverging colour map symmetric about zero, with a
//!   colour bar labelled in the map's unit and, where the caller gives the
//!   physical extent, axes in mm.
//! - [`coefficient_chart_png`] / [`coefficient_chart_svg`]: Zernike
//!   coefficients (nm) against Noll index j as bars with ±1σ error bars.
//! - [`line_plot_png`] / [`line_plot_svg`]: panels of line series side by
//!   side, on linear or logarithmic axes, with markers and legends.
//!
//! Each picture is drawn once by code generic over the `plotters` backend
//! ([`output`] holds the two writers). Pictures follow screen convention:
//! pixel (0, 0) at the top left; height-map row 0 is drawn at the top. Data
//! that leave nothing to draw (every value NaN) still give a picture, with
//! "no data" written on it, so a report never lacks a figure; wrong lengths
//! and empty inputs are errors.

mod chart;
mod font;
mod height_map;
mod lines;
mod lines_axis;
mod output;
mod svg;

use std::path::PathBuf;

pub use chart::{coefficient_chart_png, coefficient_chart_svg, MAX_BARS};
/// The embedded font, for the other pictures of the crate (`budget::picture`).
pub(crate) use font::{register as register_font, FAMILY};
pub use height_map::{height_map, height_map_png, height_map_svg, Extent, HeightMap};
pub use lines::{line_plot_png, line_plot_svg, Panel, Series, MAX_SERIES};
pub use output::Format;

/// What went wrong drawing a picture.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The picture file could not be created or written.
    #[error("{path}: cannot write the picture: {source}")]
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
    /// The embedded font could not be loaded (a corrupt build).
    #[error("the embedded font DejaVu Sans could not be registered with the plotting library")]
    Font,
    /// The plotting library failed while drawing (before anything was
    /// written).
    #[error("{path}: drawing the picture failed: {source}")]
    Draw {
        /// The file it was meant for.
        path: PathBuf,
        /// The plotting library's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
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
    /// A physical extent with an empty or non-finite side.
    #[error("the extent {x_mm:?} × {y_mm:?} mm is empty or not finite")]
    BadExtent {
        /// Its x range, mm.
        x_mm: (f64, f64),
        /// Its y range, mm.
        y_mm: (f64, f64),
    },
}

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

#[cfg(test)]
mod test_util;
