//! The two writers every picture goes through: PNG (drawn by `plotters`'
//! bitmap backend into memory, encoded with `png`) and SVG (drawn by its
//! SVG backend into a string). A picture is a [`Figure`], drawn once by
//! code generic over the backend.
//!
//! Raster content (a height map's cells) goes through [`Rasters`]: on a
//! bitmap it is resampled to the plot area and blitted; in SVG it is one
//! embedded PNG `<image>` at the map's own resolution, drawn pixelated.
//! (The `plotters` SVG backend would write one `<rect>` per pixel: its PNG
//! embedding needs a feature of `plotters-svg` this crate does not enable.)

use std::cell::RefCell;
use std::error::Error;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{font, svg, PlotError};

/// The file format of a picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// 8-bit RGB PNG.
    Png,
    /// SVG 1.1 with text as `<text>` (font family "sans-serif") and raster
    /// maps as embedded PNG images.
    Svg,
}

/// A drawing error of the plotting library, boxed.
pub(super) type DrawError = Box<dyn Error + Send + Sync>;

/// Result of drawing on backend `DB`.
pub(super) type Drawn<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A picture: its size and how to draw it.
pub(super) trait Figure {
    /// Width and height in pixels.
    fn size(&self) -> (u32, u32);

    /// Draws the whole picture on `root` (already filled white), raster
    /// content through `rasters`.
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        rasters: &Rasters,
    ) -> Drawn<DB>;
}

/// A block of RGB8 cells, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Raster {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `3 × width × height` bytes.
    pub rgb: Vec<u8>,
}

impl Raster {
    /// Nearest-neighbour resampling to `w`×`h` pixels.
    fn resampled(&self, w: usize, h: usize) -> Vec<u8> {
        let mut out = Vec::with_capacity(3 * w * h);
        for y in 0..h {
            let row = (y * self.height / h).min(self.height - 1);
            for x in 0..w {
                let col = (x * self.width / w).min(self.width - 1);
                let i = 3 * (row * self.width + col);
                out.extend_from_slice(&self.rgb[i..i + 3]);
            }
        }
        out
    }
}

/// How raster content reaches the backend.
pub(super) enum Rasters {
    /// Resampled to the area and blitted (bitmap backends).
    Blit,
    /// Kept aside and embedded after drawing (SVG), in drawing order.
    Embed(RefCell<Vec<Raster>>),
}

impl Rasters {
    /// Draws `raster` stretched over the whole of `area`.
    pub fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        raster: &Raster,
    ) -> Drawn<DB> {
        let (w, h) = area.dim_in_pixel();
        if w == 0 || h == 0 || raster.width == 0 || raster.height == 0 {
            return Ok(());
        }
        match self {
            Rasters::Blit => {
                let pixels = raster.resampled(w as usize, h as usize);
                match BitMapElement::with_owned_buffer((0, 0), (w, h), pixels) {
                    Some(element) => area.draw(&element),
                    None => Ok(()),
                }
            }
            Rasters::Embed(kept) => {
                kept.borrow_mut().push(raster.clone());
                let marker = ShapeStyle::from(svg::PLACEHOLDER).filled();
                area.draw(&Rectangle::new([(0, 0), (w as i32, h as i32)], marker))
            }
        }
    }
}

/// Writes `figure` to `path` as `format`.
///
/// # Errors
/// [`PlotError::Font`] if the embedded font cannot be loaded,
/// [`PlotError::Draw`] if the plotting library fails, [`PlotError::Io`] /
/// [`PlotError::Encode`] if the file cannot be written; all name `path`
/// where there is one.
pub(super) fn write(path: &Path, format: Format, figure: &impl Figure) -> Result<(), PlotError> {
    font::register()?;
    let drawing = |source| PlotError::Draw {
        path: path.to_path_buf(),
        source,
    };
    match format {
        Format::Png => {
            let rgb = render_rgb(figure).map_err(drawing)?;
            write_png(path, figure.size(), &rgb)
        }
        Format::Svg => {
            let text = render_svg(figure).map_err(drawing)?;
            let io = |source| PlotError::Io {
                path: path.to_path_buf(),
                source,
            };
            std::fs::write(path, text).map_err(io)
        }
    }
}

/// The picture as RGB8 pixels, row-major.
pub(super) fn render_rgb(figure: &impl Figure) -> Result<Vec<u8>, DrawError> {
    font::register().map_err(|e| Box::new(e) as DrawError)?;
    let (w, h) = figure.size();
    let mut rgb = vec![255u8; 3 * w as usize * h as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        figure.draw(&root, &Rasters::Blit)?;
        root.present()?;
    }
    Ok(rgb)
}

/// The picture as an SVG document.
pub(super) fn render_svg(figure: &impl Figure) -> Result<String, DrawError> {
    font::register().map_err(|e| Box::new(e) as DrawError)?;
    let mut text = String::new();
    let rasters = Rasters::Embed(RefCell::new(Vec::new()));
    {
        let root = SVGBackend::with_string(&mut text, figure.size()).into_drawing_area();
        root.fill(&WHITE)?;
        figure.draw(&root, &rasters)?;
        root.present()?;
    }
    let Rasters::Embed(kept) = rasters else {
        unreachable!("built as Embed above")
    };
    Ok(svg::embed_rasters(&text, &kept.into_inner()))
}

/// Encodes `rgb` (`size` pixels) as an 8-bit RGB PNG.
pub(super) fn encode_png(
    out: impl Write,
    size: (u32, u32),
    rgb: &[u8],
) -> Result<(), png::EncodingError> {
    let mut enc = png::Encoder::new(out, size.0, size.1);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()
}

fn write_png(path: &Path, size: (u32, u32), rgb: &[u8]) -> Result<(), PlotError> {
    let file = File::create(path).map_err(|source| PlotError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    encode_png(BufWriter::new(file), size, rgb).map_err(|source| PlotError::Encode {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampling_repeats_cells_and_keeps_corners() {
        let r = Raster {
            width: 2,
            height: 1,
            rgb: vec![1, 2, 3, 4, 5, 6],
        };
        let up = r.resampled(4, 2);
        assert_eq!(&up[..12], &[1, 2, 3, 1, 2, 3, 4, 5, 6, 4, 5, 6]);
        assert_eq!(up[12..], up[..12]);
        assert_eq!(r.resampled(1, 1), vec![1, 2, 3]);
    }

    #[test]
    fn png_write_error_names_the_path() {
        let p = Path::new("/nonexistent-dir-for-mfd-test/x.png");
        let err = write_png(p, (1, 1), &[0, 0, 0]).unwrap_err().to_string();
        assert!(err.contains("/nonexistent-dir-for-mfd-test/x.png"), "{err}");
    }
}
