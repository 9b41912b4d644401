//! Single grayscale camera frames as 8- or 16-bit PNG or TIFF files.

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};

/// What went wrong with an image file.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be opened or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a decodable PNG or TIFF.
    #[error("{path}: cannot decode: {problem}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        problem: String,
    },
    /// A valid image that is not an 8- or 16-bit grayscale frame.
    #[error("{path}: expected an 8- or 16-bit grayscale image, found {found}")]
    NotGray {
        /// The file.
        path: PathBuf,
        /// What the file holds.
        found: String,
    },
    /// Neither `.png` nor `.tif`/`.tiff`.
    #[error("{path}: unknown image type (expected .png, .tif or .tiff)")]
    UnknownType {
        /// The file.
        path: PathBuf,
    },
}

impl crate::outcome::Classify for ImageError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

/// A grayscale frame.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bits per sample in the file (8 or 16).
    pub bit_depth: u8,
    /// Row-major samples.
    pub data: Vec<u16>,
}

fn decode_err(path: &Path, e: impl std::fmt::Display) -> ImageError {
    ImageError::Decode {
        path: path.to_path_buf(),
        problem: e.to_string(),
    }
}

fn is_ext(path: &Path, exts: &[&str]) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| exts.iter().any(|x| e.eq_ignore_ascii_case(x)))
}

/// Reads an 8- or 16-bit grayscale PNG or TIFF (by extension).
///
/// # Errors
/// [`ImageError`] naming the file and what it found.
pub fn read_gray(path: &Path) -> Result<GrayImage, ImageError> {
    if is_ext(path, &["png"]) {
        read_png(path)
    } else if is_ext(path, &["tif", "tiff"]) {
        read_tiff(path)
    } else {
        Err(ImageError::UnknownType {
            path: path.to_path_buf(),
        })
    }
}

/// What a frame file's header says: its size and bit depth, read without
/// decoding the samples (an acquisition compares every frame's header with
/// its first frame's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GrayHeader {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bits per sample in the file (8 or 16).
    pub bit_depth: u8,
}

impl GrayImage {
    /// This frame's size and bit depth.
    pub fn header(&self) -> GrayHeader {
        GrayHeader {
            width: self.width,
            height: self.height,
            bit_depth: self.bit_depth,
        }
    }
}

impl std::fmt::Display for GrayHeader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}x{} pixels at {} bits",
            self.width, self.height, self.bit_depth
        )
    }
}

/// Reads only the header of an 8- or 16-bit grayscale PNG or TIFF.
///
/// # Errors
/// As [`read_gray`], for what the header shows.
pub fn read_gray_header(path: &Path) -> Result<GrayHeader, ImageError> {
    if is_ext(path, &["png"]) {
        let reader = png::Decoder::new(open(path)?)
            .read_info()
            .map_err(|e| decode_err(path, e))?;
        let info = reader.info();
        let bit_depth = png_gray_bits(path, info.color_type, info.bit_depth)?;
        Ok(GrayHeader {
            width: info.width,
            height: info.height,
            bit_depth,
        })
    } else if is_ext(path, &["tif", "tiff"]) {
        let mut dec = tiff::decoder::Decoder::new(open(path)?).map_err(|e| decode_err(path, e))?;
        let (width, height) = dec.dimensions().map_err(|e| decode_err(path, e))?;
        let bit_depth = match dec.colortype().map_err(|e| decode_err(path, e))? {
            tiff::ColorType::Gray(8) => 8,
            tiff::ColorType::Gray(16) => 16,
            other => {
                return Err(ImageError::NotGray {
                    path: path.to_path_buf(),
                    found: format!("{other:?}"),
                })
            }
        };
        Ok(GrayHeader {
            width,
            height,
            bit_depth,
        })
    } else {
        Err(ImageError::UnknownType {
            path: path.to_path_buf(),
        })
    }
}

/// The bits per sample of a grayscale PNG; any other colour type or depth
/// is refused by name.
fn png_gray_bits(
    path: &Path,
    color: png::ColorType,
    depth: png::BitDepth,
) -> Result<u8, ImageError> {
    match (color, depth) {
        (png::ColorType::Grayscale, png::BitDepth::Eight) => Ok(8),
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => Ok(16),
        _ => Err(ImageError::NotGray {
            path: path.to_path_buf(),
            found: format!("{color:?} at {depth:?} bits"),
        }),
    }
}

/// The largest frame a reader decodes, bytes: the largest sensor a station
/// may have (2^26 pixels, `optics::station`'s validation) at 16 bits. The
/// decoders refuse a header announcing more before allocating it (PNG's
/// own default, 64 MiB, would refuse 16-bit frames above 33 Mpx).
const MAX_FRAME_BYTES: usize = 2 << 26;

fn open(path: &Path) -> Result<BufReader<File>, ImageError> {
    File::open(path)
        .map(BufReader::new)
        .map_err(|source| ImageError::Io {
            path: path.to_path_buf(),
            source,
        })
}

fn read_png(path: &Path) -> Result<GrayImage, ImageError> {
    let limits = png::Limits {
        bytes: MAX_FRAME_BYTES,
    };
    let mut reader = png::Decoder::new_with_limits(open(path)?, limits)
        .read_info()
        .map_err(|e| decode_err(path, e))?;
    let info = reader.info();
    let (color, depth) = (info.color_type, info.bit_depth);
    let bits = png_gray_bits(path, color, depth)?;
    // The decoder's limits bound what it buffers, not the frame it asks
    // for: the header's size is checked here, before the frame is allocated.
    let (width, height) = (reader.info().width, reader.info().height);
    let frame_bytes = u64::from(width) * u64::from(height) * u64::from(bits / 8);
    if frame_bytes > MAX_FRAME_BYTES as u64 {
        return Err(decode_err(
            path,
            format!(
                "{width}x{height} pixels at {bits} bits: above the {MAX_FRAME_BYTES} bytes a \
                 frame may have (the largest sensor a station may have)"
            ),
        ));
    }
    let size = reader
        .output_buffer_size()
        .filter(|&s| s as u64 <= 2 * MAX_FRAME_BYTES as u64)
        .ok_or_else(|| decode_err(path, "image too large"))?;
    let mut buf = vec![0u8; size];
    let out = reader
        .next_frame(&mut buf)
        .map_err(|e| decode_err(path, e))?;
    let data = if bits == 8 {
        buf[..out.buffer_size()]
            .iter()
            .map(|&b| u16::from(b))
            .collect()
    } else {
        // PNG stores 16-bit samples big-endian.
        buf[..out.buffer_size()]
            .chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    };
    Ok(GrayImage {
        width: out.width,
        height: out.height,
        bit_depth: bits,
        data,
    })
}

fn read_tiff(path: &Path) -> Result<GrayImage, ImageError> {
    let mut limits = tiff::decoder::Limits::default();
    limits.decoding_buffer_size = MAX_FRAME_BYTES;
    let mut dec = tiff::decoder::Decoder::new(open(path)?)
        .map_err(|e| decode_err(path, e))?
        .with_limits(limits);
    let (width, height) = dec.dimensions().map_err(|e| decode_err(path, e))?;
    let color = dec.colortype().map_err(|e| decode_err(path, e))?;
    let not_gray = |found: String| ImageError::NotGray {
        path: path.to_path_buf(),
        found,
    };
    match color {
        tiff::ColorType::Gray(8) | tiff::ColorType::Gray(16) => {}
        other => return Err(not_gray(format!("{other:?}"))),
    }
    let (data, bit_depth) = match dec.read_image().map_err(|e| decode_err(path, e))? {
        tiff::decoder::DecodingResult::U8(v) => (v.into_iter().map(u16::from).collect(), 8),
        tiff::decoder::DecodingResult::U16(v) => (v, 16),
        _ => return Err(not_gray("a non-integer sample type".into())),
    };
    if data.len() as u64 != u64::from(width) * u64::from(height) {
        return Err(decode_err(
            path,
            format!("{} samples for {width}x{height} pixels", data.len()),
        ));
    }
    Ok(GrayImage {
        width,
        height,
        bit_depth,
        data,
    })
}

/// Writes a grayscale PNG of `bit_depth` 8 or 16 (values above 255 are
/// clipped in an 8-bit file).
///
/// # Errors
/// [`ImageError`] naming the file.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    bit_depth: u8,
    data: &[u16],
) -> Result<(), ImageError> {
    let io = |source| ImageError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = File::create(path).map_err(io)?;
    let mut enc = png::Encoder::new(BufWriter::new(file), width, height);
    enc.set_color(png::ColorType::Grayscale);
    let bytes: Vec<u8> = if bit_depth == 8 {
        enc.set_depth(png::BitDepth::Eight);
        data.iter().map(|&v| v.min(255) as u8).collect()
    } else {
        enc.set_depth(png::BitDepth::Sixteen);
        data.iter().flat_map(|v| v.to_be_bytes()).collect()
    };
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header().map_err(|e| decode_err(path, e))?;
    w.write_image_data(&bytes)
        .map_err(|e| decode_err(path, e))?;
    w.finish().map_err(|e| decode_err(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips_8_and_16_bit() {
        let dir = tempfile::tempdir().unwrap();
        for bits in [8u8, 16] {
            let p = dir.path().join(format!("f{bits}.png"));
            let max = if bits == 8 { 255 } else { 65535 };
            let data: Vec<u16> = (0..12).map(|k| (k * 997 % (max + 1)) as u16).collect();
            write_png(&p, 4, 3, bits, &data).unwrap();
            let img = read_gray(&p).unwrap();
            assert_eq!((img.width, img.height, img.bit_depth), (4, 3, bits));
            assert_eq!(img.data, data);
        }
    }

    #[test]
    fn tiff_16_bit_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.tiff");
        let data: Vec<u16> = (0..20).map(|k| k * 3000).collect();
        let mut enc = tiff::encoder::TiffEncoder::new(File::create(&p).unwrap()).unwrap();
        enc.write_image::<tiff::encoder::colortype::Gray16>(5, 4, &data)
            .unwrap();
        let img = read_gray(&p).unwrap();
        assert_eq!((img.width, img.height, img.bit_depth), (5, 4, 16));
        assert_eq!(img.data, data);
    }

    /// Regression (fuzz_readers): a PNG whose IHDR announces 65535×3145728
    /// pixels aborted allocating them (412 GB) before any pixel was read.
    #[test]
    fn png_header_sizes_are_checked_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.png");
        write_png(&p, 4, 4, 16, &[7; 16]).unwrap();
        let mut b = std::fs::read(&p).unwrap();
        // IHDR data starts at byte 16: width, height (big-endian), then its CRC at 29.
        b[16..20].copy_from_slice(&65_535u32.to_be_bytes());
        b[20..24].copy_from_slice(&3_145_728u32.to_be_bytes());
        let crc = crc32fast::hash(&b[12..29]);
        b[29..33].copy_from_slice(&crc.to_be_bytes());
        std::fs::write(&p, &b).unwrap();
        let err = read_gray(&p).unwrap_err().to_string();
        assert!(
            err.contains("65535x3145728") && err.contains("bytes a frame"),
            "{err}"
        );
    }

    #[test]
    fn colour_images_are_rejected_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rgb.png");
        let mut enc = png::Encoder::new(File::create(&p).unwrap(), 2, 2);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header()
            .unwrap()
            .write_image_data(&[0; 12])
            .unwrap();
        let err = read_gray(&p).unwrap_err().to_string();
        assert!(err.contains("rgb.png") && err.contains("Rgb"), "{err}");
        assert!(read_gray(&dir.path().join("x.bmp")).is_err());
    }
}
