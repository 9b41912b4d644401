//! A height map with a colour bar.
//!
//! ```text
//!                 title
//!                                  nm
//!        +-----------------+     +--+-
//!    y   |                 |     |  |- 60
//!   (mm) |   map (nearest  |     |  |- 40
//!        |   neighbour,    |     |  |   ...
//!        |   ≥ 400 px)     |     |  |- -60
//!        +-----------------+     +--+-
//!              x (mm)
//! ```
//!
//! Axes in mm appear when the caller gives the map's [`Extent`].

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::font::{self, LABEL_PX, TICK_PX, TITLE_PX};
use super::output::{self, Drawn, Figure, Format, Raster, Rasters};
use super::{max_abs, PlotError, NO_DATA};

/// The map's longer side is drawn at least this many pixels long (by an
/// integer zoom) ...
const MAP_MIN: usize = 400;
/// ... and at most this many (by nearest-neighbour subsampling).
const MAP_MAX: usize = 800;
/// Blank border around the picture.
const MARGIN: u32 = 16;
/// Colour bar width, its gap from the map, and the room right of it for
/// tick marks and labels.
const BAR_W: u32 = 24;
const BAR_GAP: u32 = 28;
const BAR_LABELS_W: u32 = 72;
/// The bar is at least this tall, so that its tick labels never touch.
const BAR_MIN_H: u32 = 200;
/// Room for tick labels and the axis name left of and below the map,
/// when it has axes.
const Y_AXIS_W: u32 = 84;
const X_AXIS_H: u32 = 60;
/// Tick mark length and the gap between mark and label.
const TICK: i32 = 6;
const LABEL_GAP: i32 = 6;
/// Most ticks on the bar; the symmetric range then gets 5 to 7.
const MAX_BAR_TICKS: usize = 7;

/// Pixels outside the aperture (NaN heights): a mid-light grey, distinct
/// from the map's near-white centre and from the white page.
pub(super) const OUTSIDE: RGBColor = RGBColor(190, 190, 190);

/// ColorBrewer "RdBu" (11 classes, reversed): dark blue for the most
/// negative value through near-white at zero to dark red for the most
/// positive; symmetric in lightness about its centre and readable by the
/// common forms of colour blindness. Interpolated linearly in sRGB.
const RDBU: [RGBColor; 11] = [
    RGBColor(5, 48, 97),
    RGBColor(33, 102, 172),
    RGBColor(67, 147, 195),
    RGBColor(146, 197, 222),
    RGBColor(209, 229, 240),
    RGBColor(247, 247, 247),
    RGBColor(253, 219, 199),
    RGBColor(244, 165, 130),
    RGBColor(214, 96, 77),
    RGBColor(178, 24, 43),
    RGBColor(103, 0, 31),
];

/// The physical extent of a height map, in mm: column 0's outer edge at
/// `x_mm.0`, the last column's at `x_mm.1`; the last row's outer edge at
/// `y_mm.0`, row 0's (the top) at `y_mm.1` (y up, as the surface grids
/// are laid out).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Left and right edges, mm.
    pub x_mm: (f64, f64),
    /// Bottom and top edges, mm.
    pub y_mm: (f64, f64),
}

/// A height map to draw: `values` row-major, `width`×`height`, row 0 at
/// the top; NaN or infinite = outside the aperture.
#[derive(Debug, Clone, Copy)]
pub struct HeightMap<'a> {
    /// Heights in `unit`.
    pub values: &'a [f64],
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Written above the picture.
    pub title: &'a str,
    /// Unit of the heights, written above the colour bar (e.g. "nm").
    pub unit: &'a str,
    /// Axes in mm when given.
    pub extent: Option<Extent>,
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

/// The bar's limit (±) and ticks: the 1-2-5 step that gives at most
/// [`MAX_BAR_TICKS`] ticks over ±`m` rounded out to a multiple of it.
fn bar_ticks(m: f64) -> (f64, Vec<f64>) {
    let mut step = 10f64.powf((2.0 * m / (MAX_BAR_TICKS - 1) as f64).log10().floor());
    let mut k = 1usize;
    loop {
        let s = step * [1.0, 2.0, 5.0][k % 3];
        // Within 1e-9 of a step counts as on it: 60.000000001 is 60.
        let n = (m / s - 1e-9).ceil().max(1.0);
        if 2.0 * n < MAX_BAR_TICKS as f64 {
            let ticks = (-(n as i64)..=n as i64).map(|i| i as f64 * s).collect();
            return (n * s, ticks);
        }
        k += 1;
        if k % 3 == 0 {
            step *= 10.0;
        }
    }
}

/// Where everything goes, in picture pixels.
#[derive(Debug, Clone, PartialEq)]
struct Layout {
    size: (u32, u32),
    /// Map plot area: left, top, width, height.
    map: (u32, u32, u32, u32),
    /// Colour bar: left, top, width, height.
    bar: (u32, u32, u32, u32),
}

impl Layout {
    fn new(m: &HeightMap) -> Self {
        let (mut w, mut h) = display_size(m.width, m.height);
        if let Some(e) = m.extent {
            // Square millimetres: the shorter side follows the extent.
            let aspect = (e.y_mm.1 - e.y_mm.0) / (e.x_mm.1 - e.x_mm.0);
            if aspect <= 1.0 {
                h = ((w as f64 * aspect).round() as usize).max(1);
            } else {
                w = ((h as f64 / aspect).round() as usize).max(1);
            }
        }
        let (w, h) = (w as u32, h as u32);
        let (left, below) = if m.extent.is_some() {
            (Y_AXIS_W, X_AXIS_H)
        } else {
            (0, TICK_PX as u32 / 2)
        };
        let bar_h = h.max(BAR_MIN_H);
        let content_w = left + w + BAR_GAP + BAR_W + BAR_LABELS_W;
        let title_w = font::text_width(m.title, TITLE_PX);
        let width = content_w.max(title_w) + 2 * MARGIN;
        // Title, a gap, the unit above the bar, a gap.
        let top = MARGIN + TITLE_PX as u32 + 14 + LABEL_PX as u32 + 10;
        let x0 = (width - content_w) / 2 + left;
        Self {
            size: (width, top + bar_h.max(h) + below + MARGIN),
            map: (x0, top, w, h),
            bar: (x0 + w + BAR_GAP, top, BAR_W, bar_h),
        }
    }
}

/// A validated height map, ready to draw.
struct Picture<'a> {
    map: HeightMap<'a>,
    layout: Layout,
    /// Colour limits ±`limit` and the bar's ticks.
    limit: f64,
    ticks: Vec<f64>,
    /// Whether any value is finite.
    any: bool,
}

impl<'a> Picture<'a> {
    fn new(map: HeightMap<'a>) -> Result<Self, PlotError> {
        if map.width == 0 || map.height == 0 {
            return Err(PlotError::Empty { argument: "values" });
        }
        let expected = map.width.saturating_mul(map.height);
        if map.values.len() != expected {
            return Err(PlotError::LengthMismatch {
                argument: "values",
                expected,
                found: map.values.len(),
            });
        }
        if let Some(e) = map.extent {
            let ok = |(a, b): (f64, f64)| a.is_finite() && b.is_finite() && a < b;
            if !ok(e.x_mm) || !ok(e.y_mm) {
                return Err(PlotError::BadExtent {
                    x_mm: e.x_mm,
                    y_mm: e.y_mm,
                });
            }
        }
        font::register()?;
        let peak = max_abs(map.values.iter().copied());
        let (limit, ticks) = bar_ticks(peak.filter(|&p| p > 0.0).unwrap_or(1.0));
        Ok(Self {
            layout: Layout::new(&map),
            map,
            limit,
            ticks,
            any: peak.is_some(),
        })
    }

    /// The colour of height `v`; NaN and infinities are [`OUTSIDE`].
    fn color(&self, scale: &DerivedColorMap<RGBColor>, v: f64) -> RGBColor {
        if v.is_finite() {
            scale.get_color_normalized(v, -self.limit, self.limit)
        } else {
            OUTSIDE
        }
    }

    /// The map's cells in colour, and the bar's gradient (top = +limit).
    fn rasters(&self) -> (Raster, Raster) {
        let scale = DerivedColorMap::new(&RDBU);
        let rgb = |c: RGBColor| [c.0, c.1, c.2];
        let cells = self
            .map
            .values
            .iter()
            .flat_map(|&v| rgb(self.color(&scale, v)));
        let rows = self.layout.bar.3 as usize;
        let bar = (0..rows).flat_map(|r| {
            let t = 1.0 - r as f64 / (rows - 1) as f64;
            rgb(self.color(&scale, self.limit * (2.0 * t - 1.0)))
        });
        let raster = |width, height, it: &mut dyn Iterator<Item = u8>| Raster {
            width,
            height,
            rgb: it.collect(),
        };
        (
            raster(self.map.width, self.map.height, &mut cells.into_iter()),
            raster(1, rows, &mut bar.into_iter()),
        )
    }

    /// The map, its frame and, with an extent, its axes in mm.
    fn draw_map<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        cells: &Raster,
        rasters: &Rasters,
    ) -> Drawn<DB> {
        let (x, y, w, h) = self.layout.map;
        let Some(e) = self.map.extent else {
            let area = root.clone().shrink((x, y), (w, h));
            rasters.draw(&area, cells)?;
            return frame(&area);
        };
        let area = root
            .clone()
            .shrink((x - Y_AXIS_W, y), (w + Y_AXIS_W, h + X_AXIS_H));
        let mut chart = ChartBuilder::on(&area)
            .y_label_area_size(Y_AXIS_W)
            .x_label_area_size(X_AXIS_H)
            .build_cartesian_2d(e.x_mm.0..e.x_mm.1, e.y_mm.0..e.y_mm.1)?;
        rasters.draw(&chart.plotting_area().strip_coord_spec(), cells)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(6)
            .y_labels(6)
            .label_style(font::text(TICK_PX))
            .axis_desc_style(font::text(LABEL_PX))
            .x_desc("x (mm)")
            .y_desc("y (mm)")
            .x_label_formatter(&|v| font::tick_label(*v))
            .y_label_formatter(&|v| font::tick_label(*v))
            .draw()?;
        frame(&chart.plotting_area().strip_coord_spec())
    }

    /// The colour bar, its ticks and labels, and the unit above it.
    fn draw_bar<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        bar: &Raster,
        rasters: &Rasters,
    ) -> Drawn<DB> {
        let (x, y, w, h) = self.layout.bar;
        let area = root.clone().shrink((x, y), (w, h));
        rasters.draw(&area, bar)?;
        frame(&area)?;
        let right = (x + w) as i32;
        let label = font::text(TICK_PX).pos(Pos::new(HPos::Left, VPos::Center));
        for &v in &self.ticks {
            let row = self.bar_row(v);
            root.draw(&PathElement::new(
                [(right, row), (right + TICK, row)],
                BLACK,
            ))?;
            let at = (right + TICK + LABEL_GAP, row);
            root.draw(&Text::new(font::tick_label(v), at, label.clone()))?;
        }
        let unit = Text::new(
            self.map.unit.to_string(),
            ((x + w / 2) as i32, y as i32 - 8),
            font::text(LABEL_PX).pos(Pos::new(HPos::Center, VPos::Bottom)),
        );
        root.draw(&unit)
    }

    /// The picture row of the bar showing value `v`.
    fn bar_row(&self, v: f64) -> i32 {
        let (_, y, _, h) = self.layout.bar;
        let t = (self.limit - v) / (2.0 * self.limit);
        y as i32 + (t * f64::from(h - 1)).round() as i32
    }
}

/// A one-pixel black outline just outside `area`.
fn frame<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>) -> Drawn<DB> {
    let (w, h) = area.dim_in_pixel();
    area.draw(&Rectangle::new(
        [(0, 0), (w as i32 - 1, h as i32 - 1)],
        BLACK,
    ))
}

impl Figure for Picture<'_> {
    fn size(&self) -> (u32, u32) {
        self.layout.size
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        rasters: &Rasters,
    ) -> Drawn<DB> {
        let title = Text::new(
            self.map.title.to_string(),
            ((self.layout.size.0 / 2) as i32, MARGIN as i32),
            font::text(TITLE_PX).pos(Pos::new(HPos::Center, VPos::Top)),
        );
        root.draw(&title)?;
        let (cells, bar) = self.rasters();
        self.draw_map(root, &cells, rasters)?;
        self.draw_bar(root, &bar, rasters)?;
        if !self.any {
            let (x, y, w, h) = self.layout.map;
            let note = Text::new(
                NO_DATA,
                ((x + w / 2) as i32, (y + h / 2) as i32),
                font::text(LABEL_PX).pos(Pos::new(HPos::Center, VPos::Center)),
            );
            root.draw(&note)?;
        }
        Ok(())
    }
}

/// Draws the height map `map` to `path` as `format`: the map on the
/// diverging blue–white–red ColorBrewer "RdBu" scale, symmetric about zero
/// with limits ±max|value| rounded out to a tick (1-2-5 steps, 5 to 7
/// ticks), a colour bar with those ticks and `unit` at the right, `title`
/// above, and axes in mm where `map.extent` is given. Cells outside the
/// aperture (NaN, infinite) are grey. The map is zoomed (nearest
/// neighbour) to at least 400 pixels on its longer side, or subsampled to
/// at most 800; with an extent its shorter side follows the extent's
/// aspect. With no finite value the picture is drawn with limits ±1 and
/// "no data" written across the map.
///
/// # Errors
/// [`PlotError::Empty`] if `width` or `height` is zero,
/// [`PlotError::LengthMismatch`] if `values` does not hold
/// `width`×`height` entries, [`PlotError::BadExtent`] for an empty or
/// non-finite extent, [`PlotError::Io`] / [`PlotError::Encode`] /
/// [`PlotError::Draw`] naming `path` if the picture cannot be written.
pub fn height_map(path: &Path, format: Format, map: &HeightMap) -> Result<(), PlotError> {
    output::write(path, format, &Picture::new(*map)?)
}

/// [`height_map`] as PNG, without axes: `values` row-major,
/// `width`×`height`, row 0 at the top, in `unit`.
///
/// # Errors
/// As [`height_map`].
pub fn height_map_png(
    path: &Path,
    values: &[f64],
    width: usize,
    height: usize,
    title: &str,
    unit: &str,
) -> Result<(), PlotError> {
    let map = HeightMap {
        values,
        width,
        height,
        title,
        unit,
        extent: None,
    };
    height_map(path, Format::Png, &map)
}

/// [`height_map_png`] as SVG.
///
/// # Errors
/// As [`height_map`].
pub fn height_map_svg(
    path: &Path,
    values: &[f64],
    width: usize,
    height: usize,
    title: &str,
    unit: &str,
) -> Result<(), PlotError> {
    let map = HeightMap {
        values,
        width,
        height,
        title,
        unit,
        extent: None,
    };
    height_map(path, Format::Svg, &map)
}

#[cfg(test)]
#[path = "height_map_tests.rs"]
mod tests;
