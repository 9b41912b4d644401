//! The camera preview: one accepted frame as the page draws it (an 8-bit
//! RGB PNG, saturated pixels in red), its histogram and saturation count,
//! and the frame's raw counts as a PNG of the recorder's kind (8-bit for
//! 8-bit cameras, 16-bit otherwise), for tools.
//!
//! Encoding runs on the server's blocking pool, never on the sequencer's
//! thread.

use base64::Engine as _;
use serde::{Deserialize, Serialize};

use super::state::Showing;
use crate::live::SharedFrame;

/// Bins of the preview's histogram, over `0..=full_scale`.
pub const HISTOGRAM_BINS: usize = 64;

/// The display image's colour of a saturated pixel.
pub const SATURATED_RGB: [u8; 3] = [255, 0, 0];

/// Errors of encoding a preview.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    /// The PNG encoder refused the frame.
    #[error("frame {frame}: encoding the {kind} PNG: {source}")]
    Png {
        /// Schedule index.
        frame: usize,
        /// `display` or `raw`.
        kind: &'static str,
        /// The encoder's error.
        #[source]
        source: png::EncodingError,
    },
    /// The serialisation of the preview failed.
    #[error("frame {frame}: writing the preview's JSON: {source}")]
    Json {
        /// Schedule index.
        frame: usize,
        /// The error.
        #[source]
        source: serde_json::Error,
    },
}

impl crate::outcome::Classify for PreviewError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        // Encoding a preview: a failure of its own (exit 1).
        None
    }
}

/// What the page gets for one frame (`GET /api/preview`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Preview {
    /// Schedule index of the frame.
    pub index: usize,
    /// The pattern it was exposed under.
    pub pattern: Showing,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Significant bits per sample.
    pub bit_depth: u8,
    /// The largest count, `2^bit_depth − 1`: a pixel at it is saturated.
    pub full_scale: u16,
    /// Pixels at full scale.
    pub saturated: usize,
    /// Smallest count.
    pub min: u16,
    /// Largest count.
    pub max: u16,
    /// Mean count.
    pub mean: f64,
    /// Pixels per bin; bin `k` holds counts `c` with
    /// `⌊c · HISTOGRAM_BINS / (full_scale + 1)⌋ = k`.
    pub histogram: Vec<u64>,
    /// The display PNG, base64: RGB, 8 bits; grey [`display_level`] for
    /// unsaturated pixels, [`SATURATED_RGB`] for saturated ones.
    pub png_base64: String,
}

/// One frame's preview, encoded.
#[derive(Debug)]
pub struct Encoded {
    /// Schedule index.
    pub index: usize,
    /// [`Preview`] as JSON.
    pub json: Vec<u8>,
    /// The raw counts as a grayscale PNG (8-bit for ≤ 8-bit frames, else 16-bit).
    pub raw_png: Vec<u8>,
}

/// The 8-bit grey level the display image gives `count` at `bit_depth`:
/// the top 8 significant bits.
pub fn display_level(count: u16, bit_depth: u8) -> u8 {
    let b = u32::from(bit_depth.clamp(1, 16));
    let c = u32::from(count);
    let level = if b >= 8 { c >> (b - 8) } else { c << (8 - b) };
    level.min(255) as u8
}

/// `2^bit_depth − 1`.
pub fn full_scale(bit_depth: u8) -> u16 {
    ((1u32 << bit_depth.clamp(1, 16)) - 1) as u16
}

/// Encodes `shared`'s frame.
///
/// # Errors
/// [`PreviewError`] naming the frame.
pub fn encode(shared: &SharedFrame) -> Result<Encoded, PreviewError> {
    let f = &shared.frame;
    let top = full_scale(f.bit_depth);
    let mut histogram = vec![0u64; HISTOGRAM_BINS];
    let (mut min, mut max, mut sum, mut saturated) = (u16::MAX, 0u16, 0u64, 0usize);
    let mut rgb = Vec::with_capacity(f.data.len() * 3);
    for &c in &f.data {
        let c_clip = c.min(top);
        histogram[(usize::from(c_clip) * HISTOGRAM_BINS) / (usize::from(top) + 1)] += 1;
        min = min.min(c);
        max = max.max(c);
        sum += u64::from(c);
        if c >= top {
            saturated += 1;
            rgb.extend_from_slice(&SATURATED_RGB);
        } else {
            let g = display_level(c, f.bit_depth);
            rgb.extend_from_slice(&[g, g, g]);
        }
    }
    let png_err = |kind| {
        move |source| PreviewError::Png {
            frame: shared.index,
            kind,
            source,
        }
    };
    let display =
        png_bytes(f.width, f.height, png::ColorType::Rgb, 8, &rgb).map_err(png_err("display"))?;
    let raw_png = if f.bit_depth <= 8 {
        let bytes: Vec<u8> = f.data.iter().map(|&v| v.min(255) as u8).collect();
        png_bytes(f.width, f.height, png::ColorType::Grayscale, 8, &bytes)
    } else {
        let bytes: Vec<u8> = f.data.iter().flat_map(|v| v.to_be_bytes()).collect();
        png_bytes(f.width, f.height, png::ColorType::Grayscale, 16, &bytes)
    }
    .map_err(png_err("raw"))?;
    let p = shared.pattern;
    let preview = Preview {
        index: shared.index,
        pattern: Showing {
            index: shared.index,
            direction_deg: p.direction_deg,
            tau: p.tau,
            phase_rad: p.phase_rad,
        },
        width: f.width,
        height: f.height,
        bit_depth: f.bit_depth,
        full_scale: top,
        saturated,
        min: if f.data.is_empty() { 0 } else { min },
        max,
        mean: sum as f64 / f.data.len().max(1) as f64,
        histogram,
        png_base64: base64::engine::general_purpose::STANDARD.encode(&display),
    };
    let json = serde_json::to_vec(&preview).map_err(|source| PreviewError::Json {
        frame: shared.index,
        source,
    })?;
    Ok(Encoded {
        index: shared.index,
        json,
        raw_png,
    })
}

fn png_bytes(
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: u8,
    data: &[u8],
) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, width, height);
    enc.set_color(color);
    enc.set_depth(if depth == 8 {
        png::BitDepth::Eight
    } else {
        png::BitDepth::Sixteen
    });
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header()?;
    w.write_image_data(data)?;
    w.finish()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquire::camera::Frame;
    use crate::acquire::patterns::Pattern;
    use std::time::Instant;

    fn frame(data: Vec<u16>, bit_depth: u8) -> SharedFrame {
        SharedFrame {
            index: 3,
            pattern: Pattern {
                direction_deg: 90.0,
                tau: 2.0,
                phase_rad: 0.5,
            },
            frame: Frame {
                width: 2,
                height: 2,
                bit_depth,
                data,
                timestamp: Instant::now(),
                sequence: 0,
                exposed_pattern: None,
            },
        }
    }

    #[test]
    fn levels_are_the_top_eight_bits() {
        assert_eq!(display_level(4095, 12), 255);
        assert_eq!(display_level(16, 12), 1);
        assert_eq!(display_level(200, 8), 200);
        assert_eq!(display_level(65535, 16), 255);
        assert_eq!(full_scale(12), 4095);
    }

    #[test]
    fn histogram_saturation_and_images_follow_the_counts() {
        let e = encode(&frame(vec![0, 100, 4095, 2048], 12)).unwrap();
        let p: Preview = serde_json::from_slice(&e.json).unwrap();
        assert_eq!((p.saturated, p.min, p.max), (1, 0, 4095));
        assert_eq!(p.histogram.iter().sum::<u64>(), 4);
        assert_eq!((p.histogram[0], p.histogram[1], p.histogram[32]), (1, 1, 1));
        assert_eq!(p.histogram[63], 1);
        let png = base64::engine::general_purpose::STANDARD
            .decode(&p.png_base64)
            .unwrap();
        let mut r = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        r.next_frame(&mut buf).unwrap();
        assert_eq!(&buf[..12], &[0, 0, 0, 6, 6, 6, 255, 0, 0, 128, 128, 128]);
        let mut r = png::Decoder::new(std::io::Cursor::new(e.raw_png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        r.next_frame(&mut buf).unwrap();
        assert_eq!(&buf[..8], &[0, 0, 0, 100, 0x0f, 0xff, 0x08, 0x00]);
    }
}
