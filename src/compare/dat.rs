//! Zygo MetroPro `.dat` files: a big-endian binary header, the intensity
//! block, then the phase block, read as the MetroPro Reference Guide
//! (section "Data file format") lays them out. Pure Rust: the format is a
//! fixed header of offsets, which no crate reads.
//!
//! The fields read, at their byte offsets (big-endian):
//!
//! | offset | field               | type    | meaning |
//! |-------:|---------------------|---------|---------|
//! | 0      | `magic_number`      | u32     | 0x881B036F, 0x881B0370 or 0x881B0371 |
//! | 4      | `header_format`     | i16     | 1, 2 or 3 (must match the magic number) |
//! | 6      | `header_size`       | i32     | 834 (formats 1, 2) or 4096 (format 3) |
//! | 60     | `ac_n_bytes`        | i32     | bytes of the intensity block after the header |
//! | 68     | `cn_width`          | u16     | phase columns |
//! | 70     | `cn_height`         | u16     | phase rows |
//! | 72     | `cn_n_bytes`        | i32     | bytes of the phase block (4 × columns × rows) |
//! | 164    | `intf_scale_factor` | f32     | S |
//! | 168    | `wavelength_in`     | f32     | W, metres |
//! | 176    | `obliquity_factor`  | f32     | O |
//! | 184    | `lateral_res`       | f32     | metres per pixel (0: not known) |
//! | 218    | `phase_res`         | i16     | R = 4096, 32768 (1) or 131072 (2, formats 2 and 3 only) |
//!
//! The phase block (i32, row-major, row 0 at the top) starts at
//! `header_size + ac_n_bytes`; values at or above 0x7FFFFFF8 mark pixels
//! without data. A height is `value · W · S · O / R` metres.

use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use super::{CompareError, InterferometerMap};

/// Phase values at or above this mark pixels without data.
pub const INVALID_PHASE: i32 = 0x7FFF_FFF8;

/// The three magic numbers, header formats and header sizes the guide
/// allows (a rigorous reader checks all three).
pub const KNOWN_HEADERS: [(u32, i16, i32); 3] = [
    (0x881B_036F, 1, 834),
    (0x881B_0370, 2, 834),
    (0x881B_0371, 3, 4096),
];

/// The fields of a header that the comparison uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Header {
    /// 1, 2 or 3.
    pub header_format: i16,
    /// Bytes of the header.
    pub header_size: usize,
    /// Bytes of the intensity block.
    pub ac_n_bytes: usize,
    /// Phase columns.
    pub cn_width: usize,
    /// Phase rows.
    pub cn_height: usize,
    /// S.
    pub intf_scale_factor: f64,
    /// W, m.
    pub wavelength_m: f64,
    /// O.
    pub obliquity_factor: f64,
    /// m per pixel, 0 when not known.
    pub lateral_res_m: f64,
    /// R, phase counts per fringe.
    pub resolution: f64,
}

fn be_u32(b: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}
fn be_i32(b: &[u8], at: usize) -> i32 {
    be_u32(b, at) as i32
}
fn be_i16(b: &[u8], at: usize) -> i16 {
    i16::from_be_bytes([b[at], b[at + 1]])
}
fn be_u16(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}
fn be_f32(b: &[u8], at: usize) -> f64 {
    f64::from(f32::from_bits(be_u32(b, at)))
}

/// Reads and checks the header of `bytes` (the whole file).
///
/// # Errors
/// [`CompareError::Header`] naming the field whose value the guide does not
/// allow; [`CompareError::Truncated`] when the file is shorter than its header.
pub fn header(path: &Path, bytes: &[u8]) -> Result<Header, CompareError> {
    let bad = |field: &'static str, found: String, expected: &str| CompareError::Header {
        path: path.to_path_buf(),
        field,
        found,
        expected: expected.to_string(),
    };
    if bytes.len() < 834 {
        return Err(CompareError::Truncated {
            path: path.to_path_buf(),
            what: "the MetroPro header",
            offset: 0,
            expected: 834,
            found: bytes.len(),
        });
    }
    let magic = be_u32(bytes, 0);
    let format = be_i16(bytes, 4);
    let size = be_i32(bytes, 6);
    let Some(&(_, _, known_size)) = KNOWN_HEADERS.iter().find(|(m, _, _)| *m == magic) else {
        return Err(bad(
            "magic_number",
            format!("{magic:#010X}"),
            "0x881B036F, 0x881B0370 or 0x881B0371 (a MetroPro data file)",
        ));
    };
    if !KNOWN_HEADERS.contains(&(magic, format, known_size)) {
        return Err(bad(
            "header_format",
            format.to_string(),
            &format!("the format of magic number {magic:#010X}"),
        ));
    }
    if size != known_size {
        return Err(bad(
            "header_size",
            size.to_string(),
            &format!("{known_size} for header format {format}"),
        ));
    }
    let header_size = size as usize;
    if bytes.len() < header_size {
        return Err(CompareError::Truncated {
            path: path.to_path_buf(),
            what: "the MetroPro header",
            offset: 0,
            expected: header_size,
            found: bytes.len(),
        });
    }
    let ac_n_bytes = be_i32(bytes, 60);
    let (w, h) = (be_u16(bytes, 68) as usize, be_u16(bytes, 70) as usize);
    let cn_n_bytes = be_i32(bytes, 72);
    if ac_n_bytes < 0 {
        return Err(bad("ac_n_bytes", ac_n_bytes.to_string(), "≥ 0"));
    }
    if w == 0 || h == 0 {
        return Err(bad(
            "cn_width, cn_height",
            format!("{w} × {h}"),
            "a phase map (both > 0)",
        ));
    }
    if i64::from(cn_n_bytes) != 4 * (w * h) as i64 {
        return Err(bad(
            "cn_n_bytes",
            cn_n_bytes.to_string(),
            &format!("4 × cn_width × cn_height = {}", 4 * w * h),
        ));
    }
    let phase_res = be_i16(bytes, 218);
    let resolution = match (format, phase_res) {
        (_, 0) => 4096.0,
        (_, 1) => 32768.0,
        (2 | 3, 2) => 131_072.0,
        _ => {
            return Err(bad(
                "phase_res",
                phase_res.to_string(),
                &format!(
                    "0 or 1{} for header format {format}",
                    if format == 1 { "" } else { " or 2" }
                ),
            ))
        }
    };
    let positive = |field: &'static str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(bad(field, v.to_string(), "a positive number"))
        }
    };
    let lateral = be_f32(bytes, 184);
    Ok(Header {
        header_format: format,
        header_size,
        ac_n_bytes: ac_n_bytes as usize,
        cn_width: w,
        cn_height: h,
        intf_scale_factor: positive("intf_scale_factor", be_f32(bytes, 164))?,
        wavelength_m: positive("wavelength_in", be_f32(bytes, 168))?,
        obliquity_factor: positive("obliquity_factor", be_f32(bytes, 176))?,
        lateral_res_m: if lateral.is_finite() && lateral > 0.0 {
            lateral
        } else {
            0.0
        },
        resolution,
    })
}

/// Reads a MetroPro `.dat` file's phase map as heights. The file must be
/// a plain file of exactly the header's size, header, intensity and phase
/// blocks; no more than that is read (a link to `/dev/zero` is refused
/// before a byte of it is, a longer file by its length).
///
/// # Errors
/// [`CompareError`] naming the file and the field.
pub fn read(path: &Path) -> Result<InterferometerMap, CompareError> {
    let io = |source| CompareError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(CompareError::Length {
            path: path.to_path_buf(),
            problem: "not a plain file (a device, a pipe or a folder): a MetroPro file has the \
                      size its header gives"
                .into(),
        });
    }
    // The largest header a known format has, then the blocks it announces.
    let largest_header = KNOWN_HEADERS.iter().map(|k| k.2 as u64).max().unwrap_or(0);
    let mut reader = file.take(largest_header);
    let mut bytes = Vec::new();
    reader.read_to_end(&mut bytes).map_err(io)?;
    let h = header(path, &bytes)?;
    let start = h.header_size + h.ac_n_bytes;
    let n = h.cn_width * h.cn_height;
    let total = (start + 4 * n) as u64;
    if meta.len() > total {
        return Err(CompareError::Length {
            path: path.to_path_buf(),
            problem: format!(
                "{} bytes, where its header gives {total} (header {} + intensity {} + \
                 phase 4 × {} × {}): not one MetroPro map",
                meta.len(),
                h.header_size,
                h.ac_n_bytes,
                h.cn_width,
                h.cn_height
            ),
        });
    }
    let mut file = reader.into_inner();
    bytes.truncate(h.header_size);
    file.seek(SeekFrom::Start(h.header_size as u64))
        .map_err(io)?;
    file.take(total - h.header_size as u64)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() < start + 4 * n {
        return Err(CompareError::Truncated {
            path: path.to_path_buf(),
            what: "the phase block",
            offset: start,
            expected: 4 * n,
            found: bytes.len().saturating_sub(start),
        });
    }
    let nm_per_count =
        h.wavelength_m * h.intf_scale_factor * h.obliquity_factor / h.resolution * 1e9;
    let heights_nm = (0..n)
        .map(|k| {
            let v = be_i32(&bytes, start + 4 * k);
            if v >= INVALID_PHASE {
                f64::NAN
            } else {
                f64::from(v) * nm_per_count
            }
        })
        .collect();
    Ok(InterferometerMap {
        path: path.to_path_buf(),
        format: "MetroPro .dat",
        width: h.cn_width,
        height: h.cn_height,
        heights_nm,
        pixel_mm: (h.lateral_res_m > 0.0).then_some(h.lateral_res_m * 1e3),
        wavelength_nm: Some(h.wavelength_m * 1e9),
    })
}
