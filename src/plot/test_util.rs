//! Pictures read back for the tests: RGB8 pixels with a few queries.

use std::path::Path;

/// One pixel: red, green, blue.
pub type Rgb = [u8; 3];
/// The page.
pub const WHITE: Rgb = [255, 255, 255];

/// A row-major RGB8 picture.
pub struct Pixels {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
}

impl Pixels {
    /// Wraps `rgb` of a `size` picture.
    pub fn new(size: (u32, u32), rgb: Vec<u8>) -> Self {
        assert_eq!(rgb.len(), 3 * size.0 as usize * size.1 as usize);
        Self {
            width: size.0 as usize,
            height: size.1 as usize,
            rgb,
        }
    }

    /// Reads an 8-bit RGB PNG.
    pub fn read_png(path: &Path) -> Self {
        let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
        let mut reader = png::Decoder::new(file).read_info().unwrap();
        let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        buf.truncate(info.buffer_size());
        Self::new((info.width, info.height), buf)
    }

    /// The pixel at (`x`, `y`).
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        assert!(x < self.width && y < self.height, "({x}, {y}) off picture");
        let i = 3 * (y * self.width + x);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Pixels inside the `w`×`h` box at (`x`, `y`) that `pred` accepts.
    pub fn count(
        &self,
        x: usize,
        y: usize,
        w: usize,
        h: usize,
        pred: impl Fn(Rgb) -> bool,
    ) -> usize {
        (y..(y + h).min(self.height))
            .flat_map(|r| (x..(x + w).min(self.width)).map(move |c| (c, r)))
            .filter(|&(c, r)| pred(self.get(c, r)))
            .count()
    }

    /// Dark (text or line) pixels inside the box.
    pub fn ink(&self, x: usize, y: usize, w: usize, h: usize) -> usize {
        self.count(x, y, w, h, is_dark)
    }
}

/// Nearly black: text, axes, error bars (anti-aliased edges excluded).
pub fn is_dark(p: Rgb) -> bool {
    p.iter().all(|&c| c < 90)
}

/// The column `plotters` gives value `v` on an axis `lo..hi` over a plot
/// area `w` pixels wide starting at column `x0`.
pub fn column(v: f64, (lo, hi): (f64, f64), x0: u32, w: u32) -> usize {
    let t = (v - lo) / (hi - lo);
    (f64::from(x0) + (f64::from(w - 1) * t + 1e-3).floor()) as usize
}

/// The row `plotters` gives value `v` on an axis `lo..hi` (up) over a plot
/// area `h` pixels tall starting at row `y0`.
pub fn row(v: f64, (lo, hi): (f64, f64), y0: u32, h: u32) -> usize {
    let t = (v - lo) / (hi - lo);
    (f64::from(y0 + h - 1) + (-f64::from(h - 1) * t - 1e-3).ceil()) as usize
}
