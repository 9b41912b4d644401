//! Pixel conversions and control mappings of the hardware backends, as
//! plain functions: always built and tested, whatever features are on.
//!
//! Every conversion takes the driver's buffer with its line stride
//! (bytes per row, ≥ the packed row) and writes row-major `u16` counts.

/// A buffer that does not hold the frame it claims to.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{format}: {width}x{height} with stride {stride} needs {needed} bytes, the buffer has {found}"
)]
pub struct SizeError {
    /// Pixel format name.
    pub format: &'static str,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes per row in the buffer.
    pub stride: usize,
    /// Bytes needed.
    pub needed: usize,
    /// Bytes present.
    pub found: usize,
}

impl crate::outcome::Classify for SizeError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        // A buffer from the camera shorter than its format says.
        Some(Outcome::Device)
    }
}

/// Frame layout in a driver buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes per row; 0 for packed rows.
    pub stride: usize,
}

fn rows<'a>(
    src: &'a [u8],
    layout: Layout,
    bytes_per_pixel: usize,
    format: &'static str,
) -> Result<impl Iterator<Item = &'a [u8]>, SizeError> {
    let packed = layout.width * bytes_per_pixel;
    let stride = if layout.stride == 0 {
        packed
    } else {
        layout.stride
    };
    let needed = if layout.height == 0 {
        0
    } else {
        stride * (layout.height - 1) + packed
    };
    if stride < packed || src.len() < needed {
        return Err(SizeError {
            format,
            width: layout.width,
            height: layout.height,
            stride,
            needed,
            found: src.len(),
        });
    }
    Ok((0..layout.height).map(move |r| &src[r * stride..r * stride + packed]))
}

/// 8-bit grayscale (GenICam Mono8, V4L2 `GREY`).
///
/// # Errors
/// [`SizeError`] when the buffer is short.
pub fn mono8(src: &[u8], layout: Layout, out: &mut Vec<u16>) -> Result<(), SizeError> {
    out.clear();
    for row in rows(src, layout, 1, "Mono8")? {
        out.extend(row.iter().map(|&b| u16::from(b)));
    }
    Ok(())
}

/// 16-bit little-endian samples: GenICam Mono16, Mono12 (12 bits in a
/// 16-bit container) and V4L2 `Y16`. Values above `2^bits − 1` are errors
/// of the device, kept as they are.
///
/// # Errors
/// [`SizeError`] when the buffer is short.
pub fn mono16le(src: &[u8], layout: Layout, out: &mut Vec<u16>) -> Result<(), SizeError> {
    out.clear();
    for row in rows(src, layout, 2, "Mono16")? {
        out.extend(
            row.chunks_exact(2)
                .map(|p| u16::from_le_bytes([p[0], p[1]])),
        );
    }
    Ok(())
}

/// The luma of V4L2 `YUYV` (YUV 4:2:2, bytes `Y0 U Y1 V`): the Y bytes.
///
/// # Errors
/// [`SizeError`] when the buffer is short.
pub fn yuyv_luma(src: &[u8], layout: Layout, out: &mut Vec<u16>) -> Result<(), SizeError> {
    out.clear();
    for row in rows(src, layout, 2, "YUYV")? {
        out.extend(row.iter().step_by(2).map(|&y| u16::from(y)));
    }
    Ok(())
}

/// A V4L2 integer control's range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlRange {
    /// Smallest value.
    pub min: i64,
    /// Largest value.
    pub max: i64,
    /// Step (≥ 1).
    pub step: i64,
    /// Driver default.
    pub default: i64,
}

/// A requested setting the device cannot take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{requested} {unit} is {value} in device units, outside [{min}, {max}]")]
pub struct RangeError {
    /// What was asked.
    pub requested: f64,
    /// Its unit.
    pub unit: &'static str,
    /// Device units it maps to.
    pub value: i64,
    /// Smallest device value.
    pub min: i64,
    /// Largest device value.
    pub max: i64,
}

impl crate::outcome::Classify for RangeError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        // A setting asked for (exposure, gain) outside the device's range.
        Some(Outcome::Input)
    }
}

fn snap(
    requested: f64,
    unit: &'static str,
    raw: f64,
    range: ControlRange,
) -> Result<i64, RangeError> {
    let step = range.step.max(1);
    let value = range.min + ((raw - range.min as f64) / step as f64).round() as i64 * step;
    if !raw.is_finite() || value < range.min || value > range.max {
        return Err(RangeError {
            requested,
            unit,
            value,
            min: range.min,
            max: range.max,
        });
    }
    Ok(value)
}

/// `V4L2_CID_EXPOSURE_ABSOLUTE` counts 100 µs units: the value for
/// `exposure_us`, snapped to the control's step.
///
/// # Errors
/// [`RangeError`] outside the control's range.
pub fn v4l2_exposure(exposure_us: f64, range: ControlRange) -> Result<i64, RangeError> {
    snap(exposure_us, "µs", exposure_us / 100.0, range)
}

/// `V4L2_CID_GAIN` has no unit. We take the driver default as 0 dB and the
/// control as linear in amplitude (true of most sensor gain registers):
/// `value = default · 10^(gain_db / 20)`, snapped to the step.
///
/// # Errors
/// [`RangeError`] outside the control's range, or a default of 0 (no
/// reference level).
pub fn v4l2_gain(gain_db: f64, range: ControlRange) -> Result<i64, RangeError> {
    if range.default <= 0 {
        return Err(RangeError {
            requested: gain_db,
            unit: "dB",
            value: range.default,
            min: range.min,
            max: range.max,
        });
    }
    let raw = range.default as f64 * 10f64.powf(gain_db / 20.0);
    snap(gain_db, "dB", raw, range)
}

/// A monotonic frame counter from GigE Vision stream frame ids: 16-bit
/// ids run 1…65535 and skip 0 when they wrap, so a wrap adds 65535; larger
/// (64-bit) ids pass through. A step back by less than half the 16-bit
/// range is a late (reordered or retried) frame, not a wrap, and keeps its
/// place.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameIdUnwrap {
    last: Option<u64>,
    wraps: u64,
}

impl FrameIdUnwrap {
    /// The counter value of the frame with id `raw`.
    pub fn unwrap(&mut self, raw: u64) -> u64 {
        const HALF: u64 = 0x8000;
        let Some(last) = self.last.filter(|&l| l <= 0xFFFF && raw <= 0xFFFF) else {
            self.last = Some(raw);
            return self.wraps * 0xFFFF + raw;
        };
        if raw < last && last - raw > HALF {
            self.wraps += 1;
        } else if raw > last && raw - last > HALF {
            // A late frame from before the last wrap.
            return self.wraps.saturating_sub(1) * 0xFFFF + raw;
        } else if raw < last {
            return self.wraps * 0xFFFF + raw;
        }
        self.last = Some(raw);
        self.wraps * 0xFFFF + raw
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packed(width: usize, height: usize) -> Layout {
        Layout {
            width,
            height,
            stride: 0,
        }
    }

    #[test]
    fn mono8_honours_the_stride() {
        // Two rows of three pixels, rows padded to 4 bytes (padding 0xEE).
        let src = [1, 2, 3, 0xEE, 4, 5, 255, 0xEE];
        let mut out = Vec::new();
        let layout = Layout {
            width: 3,
            height: 2,
            stride: 4,
        };
        mono8(&src, layout, &mut out).unwrap();
        assert_eq!(out, [1, 2, 3, 4, 5, 255]);
        // The last row need not carry its padding.
        mono8(&src[..7], layout, &mut out).unwrap();
        assert_eq!(out.len(), 6);
        assert!(mono8(&src[..6], layout, &mut out).is_err());
    }

    #[test]
    fn mono16_is_little_endian() {
        let values = [0u16, 1, 0x0FFF, 0x1234, 0xFFFF, 0x8000];
        let src: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut out = Vec::new();
        mono16le(&src, packed(3, 2), &mut out).unwrap();
        assert_eq!(out, values);
        let err = mono16le(&src[..11], packed(3, 2), &mut out).unwrap_err();
        assert_eq!((err.needed, err.found), (12, 11));
    }

    #[test]
    fn yuyv_keeps_the_y_bytes() {
        // Y0 U Y1 V for 4 pixels on one row: Y = 10, 20, 30, 40.
        let src = [10, 128, 20, 128, 30, 64, 40, 192];
        let mut out = Vec::new();
        yuyv_luma(&src, packed(4, 1), &mut out).unwrap();
        assert_eq!(out, [10, 20, 30, 40]);
        // A stride narrower than the packed row is refused.
        let bad = Layout {
            width: 4,
            height: 1,
            stride: 4,
        };
        assert!(yuyv_luma(&src, bad, &mut out).is_err());
    }

    #[test]
    fn exposure_maps_to_100_us_units() {
        let range = ControlRange {
            min: 1,
            max: 5000,
            step: 1,
            default: 156,
        };
        assert_eq!(v4l2_exposure(10_000.0, range), Ok(100));
        assert_eq!(v4l2_exposure(149.0, range), Ok(1));
        assert!(v4l2_exposure(600_000.0, range).is_err());
        assert!(v4l2_exposure(f64::NAN, range).is_err());
        let stepped = ControlRange { step: 4, ..range };
        // 1 + round((25 − 1)/4)·4 = 25; 1 + round((26.5 − 1)/4)·4 = 25.
        assert_eq!(v4l2_exposure(2650.0, stepped), Ok(25));
    }

    #[test]
    fn gain_db_scales_the_default_linearly() {
        let range = ControlRange {
            min: 0,
            max: 255,
            step: 1,
            default: 32,
        };
        assert_eq!(v4l2_gain(0.0, range), Ok(32));
        // +6.0206 dB doubles the amplitude: 64; −6.0206 dB halves it: 16.
        assert_eq!(v4l2_gain(20.0 * 2f64.log10(), range), Ok(64));
        assert_eq!(v4l2_gain(-20.0 * 2f64.log10(), range), Ok(16));
        assert!(v4l2_gain(30.0, range).is_err());
        assert!(v4l2_gain(
            0.0,
            ControlRange {
                default: 0,
                ..range
            }
        )
        .is_err());
    }

    #[test]
    fn gvsp_frame_ids_unwrap_across_the_skipped_zero() {
        let mut u = FrameIdUnwrap::default();
        // The fake camera starts near the top of the 16-bit range.
        let ids = [65533, 65534, 65535, 1, 2, 3];
        let seq: Vec<u64> = ids.iter().map(|&r| u.unwrap(r)).collect();
        assert_eq!(seq, [65533, 65534, 65535, 65536, 65537, 65538]);
        // A late frame (id 2 again, or one from before the wrap) is older.
        assert_eq!(u.unwrap(2), 65537);
        assert_eq!(u.unwrap(65534), 65534);
        assert_eq!(u.unwrap(4), 65539);
        // A reordered pair far from any wrap.
        let mut u = FrameIdUnwrap::default();
        assert_eq!(
            [u.unwrap(100), u.unwrap(102), u.unwrap(101), u.unwrap(103)],
            [100, 102, 101, 103]
        );
        // 64-bit ids pass through.
        let mut u = FrameIdUnwrap::default();
        assert_eq!([u.unwrap(70_000), u.unwrap(70_001)], [70_000, 70_001]);
    }
}
