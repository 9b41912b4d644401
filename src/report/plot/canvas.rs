//! An RGB8 raster with the few drawing operations the plots need, written
//! out as an 8-bit RGB PNG.
//!
//! Pixel (0, 0) is the top-left corner; x grows right, y grows down.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use super::PlotError;

/// One pixel: red, green, blue.
pub type Rgb = [u8; 3];

/// Page background.
pub const WHITE: Rgb = [255, 255, 255];
/// Text, axes, error bars.
pub const BLACK: Rgb = [0, 0, 0];

/// A row-major RGB8 picture.
#[derive(Debug, Clone)]
pub struct Canvas {
    width: usize,
    height: usize,
    pixels: Vec<Rgb>,
}

impl Canvas {
    /// A `width`×`height` canvas filled with `background`.
    pub fn new(width: usize, height: usize, background: Rgb) -> Self {
        Self {
            width,
            height,
            pixels: vec![background; width * height],
        }
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixel at (`x`, `y`).
    ///
    /// # Panics
    /// When (`x`, `y`) lies off the canvas.
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        assert!(x < self.width && y < self.height, "({x}, {y}) off canvas");
        self.pixels[y * self.width + x]
    }

    /// Sets the pixel at (`x`, `y`); off-canvas coordinates are ignored.
    pub fn set(&mut self, x: i64, y: i64, color: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = color;
        }
    }

    /// Fills the `w`×`h` rectangle whose top-left corner is (`x`, `y`),
    /// clipped to the canvas.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: usize, h: usize, color: Rgb) {
        let x0 = x.clamp(0, self.width as i64) as usize;
        let y0 = y.clamp(0, self.height as i64) as usize;
        let x1 = (x + w as i64).clamp(0, self.width as i64) as usize;
        let y1 = (y + h as i64).clamp(0, self.height as i64) as usize;
        for row in y0..y1 {
            self.pixels[row * self.width + x0..row * self.width + x1.max(x0)].fill(color);
        }
    }

    /// A one-pixel horizontal line from `x0` to `x1` inclusive on row `y`.
    pub fn hline(&mut self, x0: i64, x1: i64, y: i64, color: Rgb) {
        let (a, b) = (x0.min(x1), x0.max(x1));
        self.fill_rect(a, y, (b - a + 1) as usize, 1, color);
    }

    /// A one-pixel vertical line from `y0` to `y1` inclusive in column `x`.
    pub fn vline(&mut self, x: i64, y0: i64, y1: i64, color: Rgb) {
        let (a, b) = (y0.min(y1), y0.max(y1));
        self.fill_rect(x, a, 1, (b - a + 1) as usize, color);
    }

    /// The outline of the `w`×`h` rectangle at (`x`, `y`), one pixel wide.
    pub fn stroke_rect(&mut self, x: i64, y: i64, w: usize, h: usize, color: Rgb) {
        let (x1, y1) = (x + w as i64 - 1, y + h as i64 - 1);
        self.hline(x, x1, y, color);
        self.hline(x, x1, y1, color);
        self.vline(x, y, y1, color);
        self.vline(x1, y, y1, color);
    }

    /// Writes the canvas as an 8-bit RGB PNG.
    ///
    /// # Errors
    /// [`PlotError::Io`] when the file cannot be created,
    /// [`PlotError::Encode`] when the PNG encoder fails; both name `path`.
    pub fn write_png(&self, path: &Path) -> Result<(), PlotError> {
        let file = File::create(path).map_err(|source| PlotError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let encode = |source| PlotError::Encode {
            path: path.to_path_buf(),
            source,
        };
        let (w, h) = (self.width as u32, self.height as u32);
        let mut enc = png::Encoder::new(BufWriter::new(file), w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().map_err(encode)?;
        writer
            .write_image_data(self.pixels.as_flattened())
            .map_err(encode)?;
        writer.finish().map_err(encode)
    }
}

/// Reads an RGB8 PNG back as a canvas (for tests).
#[cfg(test)]
pub fn read_png(path: &Path) -> Canvas {
    let file = std::io::BufReader::new(File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let pixels = buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    Canvas {
        width: info.width as usize,
        height: info.height as usize,
        pixels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_keeps_pixels() {
        let mut c = Canvas::new(7, 5, WHITE);
        c.fill_rect(1, 1, 3, 2, [10, 200, 30]);
        c.set(6, 4, [1, 2, 3]);
        c.set(-1, 9, BLACK); // off canvas: ignored
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.png");
        c.write_png(&p).unwrap();
        let back = read_png(&p);
        assert_eq!((back.width(), back.height()), (7, 5));
        assert_eq!(back.pixels, c.pixels);
        assert_eq!(back.get(3, 2), [10, 200, 30]);
        assert_eq!(back.get(4, 2), WHITE);
    }

    #[test]
    fn write_error_names_the_path() {
        let c = Canvas::new(2, 2, WHITE);
        let p = Path::new("/nonexistent-dir-for-mfd-test/x.png");
        let err = c.write_png(p).unwrap_err().to_string();
        assert!(err.contains("/nonexistent-dir-for-mfd-test/x.png"), "{err}");
    }

    #[test]
    fn clipped_rectangles_stay_on_canvas() {
        let mut c = Canvas::new(4, 4, WHITE);
        c.fill_rect(-2, -2, 3, 3, BLACK);
        c.fill_rect(3, 3, 10, 10, BLACK);
        assert_eq!(c.get(0, 0), BLACK);
        assert_eq!(c.get(1, 1), WHITE);
        assert_eq!(c.get(3, 3), BLACK);
    }
}
