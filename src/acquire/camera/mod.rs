//! Cameras: one narrow [`Camera`] trait and its backends.
//!
//! - `sim` (always built): the simulated station's camera
//!   ([`crate::sim::SimulatedCamera`], which lives with the rest of the
//!   simulated station in [`crate::sim`]), looking at whatever pattern a
//!   shared screen state says is on the screen, with injected faults.
//! - `aravis` (feature `aravis`): GigE Vision and USB3 Vision cameras through
//!   libaravis 0.8, and an in-process GigE Vision fake camera on loopback
//!   serving the simulated station.
//! - `v4l` (feature `v4l`): Video4Linux2 devices (`/dev/videoN`).
//!
//! Backends are chosen by a [`CameraSpec`] string (`sim`, `aravis`,
//! `aravis:ID`, `aravis:fake`, `v4l:/dev/videoN`); one that was not compiled
//! in answers [`CameraError::NotBuilt`] naming its feature. Opening the camera
//! a spec names is `live::camera::open`, above the simulated station (which
//! serves `sim` and `aravis:fake`); `acquire` uses nothing of `sim`.

#[cfg(feature = "aravis")]
pub mod aravis;
pub mod convert;
mod error;
#[cfg(feature = "v4l")]
pub mod v4l;

use std::str::FromStr;
use std::time::{Duration, Instant};

pub use error::CameraError;

/// Pixel formats the backends deliver (all stored as `u16` counts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// 8 bits per pixel.
    Mono8,
    /// 12 significant bits in a 16-bit little-endian container.
    Mono12,
    /// 16 bits per pixel, little-endian.
    Mono16,
}

impl PixelFormat {
    /// Significant bits per sample.
    pub fn bit_depth(self) -> u8 {
        match self {
            PixelFormat::Mono8 => 8,
            PixelFormat::Mono12 => 12,
            PixelFormat::Mono16 => 16,
        }
    }

    /// The format that carries `bits` significant bits.
    pub fn from_bit_depth(bits: u32) -> Option<Self> {
        match bits {
            8 => Some(PixelFormat::Mono8),
            12 => Some(PixelFormat::Mono12),
            16 => Some(PixelFormat::Mono16),
            _ => None,
        }
    }
}

/// How frames are started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriggerMode {
    /// One exposure per [`Camera::trigger`] call.
    Software,
    /// The camera exposes continuously at its frame rate.
    FreeRunning,
}

/// A region of interest in sensor pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    /// First column.
    pub x: u32,
    /// First row.
    pub y: u32,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

/// What a camera is and can do.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Backend name (`sim`, `aravis`, `v4l`).
    pub backend: &'static str,
    /// Device identifier (Aravis ID, device path, `sim`).
    pub id: String,
    /// Vendor and model, as the device reports them.
    pub model: String,
    /// Full sensor size `(width, height)`, pixels.
    pub sensor: (u32, u32),
    /// Current frame size `(width, height)`, pixels.
    pub resolution: (u32, u32),
    /// Formats [`Camera::configure`] accepts.
    pub pixel_formats: Vec<PixelFormat>,
    /// Whether [`TriggerMode::Software`] is honoured.
    pub software_trigger: bool,
}

/// Settings applied by [`Camera::configure`]; `None` leaves the device's value.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraConfig {
    /// Exposure time, µs.
    pub exposure_us: Option<f64>,
    /// Analogue gain, dB.
    pub gain_db: Option<f64>,
    /// Pixel format.
    pub pixel_format: Option<PixelFormat>,
    /// Region of interest; `None` for the whole sensor.
    pub region: Option<Region>,
    /// Triggered or free running.
    pub trigger: TriggerMode,
    /// Frame rate when free running, frames/s.
    pub frame_rate_hz: Option<f64>,
    /// Driver buffers to keep in flight.
    pub buffers: usize,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            exposure_us: None,
            gain_db: None,
            pixel_format: None,
            region: None,
            trigger: TriggerMode::Software,
            frame_rate_hz: None,
            buffers: 8,
        }
    }
}

/// One frame from a camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Row-major counts, `width · height`.
    pub data: Vec<u16>,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Significant bits per sample.
    pub bit_depth: u8,
    /// Host time at which the exposure started, as well as the backend
    /// knows it (see each backend).
    pub timestamp: Instant,
    /// The device's frame counter: consecutive frames differ by one, a gap
    /// means frames were lost.
    pub sequence: u64,
    /// Schedule index of the pattern the device knows was on the screen
    /// during the exposure: set by simulated devices (the simulated camera,
    /// the Aravis fake camera served in-process), `None` for real cameras.
    pub exposed_pattern: Option<usize>,
}

/// Figures of the stream since it started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StreamStatistics {
    /// Buffers completed.
    pub completed: u64,
    /// Buffers that failed (missing packets, timeouts, size mismatches).
    pub failures: u64,
    /// Frames that found no free buffer.
    pub underruns: u64,
    /// GigE Vision packets resent on request.
    pub resent_packets: u64,
    /// GigE Vision packets never received.
    pub missing_packets: u64,
}

/// A camera. Narrow on purpose: vendor extras are typed methods of a backend.
pub trait Camera: Send {
    /// What the device is.
    fn describe(&self) -> CameraInfo;
    /// Applies `config`; call before [`Camera::start`].
    ///
    /// # Errors
    /// [`CameraError::Config`] naming the setting the device refused.
    fn configure(&mut self, config: &CameraConfig) -> Result<(), CameraError>;
    /// Starts streaming.
    ///
    /// # Errors
    /// [`CameraError`] from the device.
    fn start(&mut self) -> Result<(), CameraError>;
    /// Stops streaming (also done on drop).
    ///
    /// # Errors
    /// [`CameraError`] from the device.
    fn stop(&mut self) -> Result<(), CameraError>;
    /// The next frame, waiting at most `timeout`.
    ///
    /// # Errors
    /// [`CameraError::Timeout`] when none came, [`CameraError::Disconnected`]
    /// when the device is gone.
    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError>;
    /// Transport figures since [`Camera::start`], where the backend has them.
    fn stream_statistics(&self) -> Option<StreamStatistics> {
        None
    }
    /// Starts one exposure (software trigger).
    ///
    /// # Errors
    /// [`CameraError::Unsupported`] where the device has no software trigger.
    fn trigger(&mut self) -> Result<(), CameraError> {
        Err(CameraError::Unsupported {
            device: self.describe().id,
            what: "software trigger".into(),
        })
    }
}

/// A camera named on the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CameraSpec {
    /// The simulated camera.
    Sim,
    /// An Aravis camera: the first one found, or the one with this ID;
    /// `fake` starts the GigE Vision fake camera on loopback.
    Aravis(Option<String>),
    /// A V4L2 device path.
    V4l(String),
}

impl FromStr for CameraSpec {
    type Err = CameraError;

    fn from_str(s: &str) -> Result<Self, CameraError> {
        let (kind, rest) = s.split_once(':').map_or((s, None), |(k, r)| (k, Some(r)));
        match (kind, rest) {
            ("sim", None) => Ok(CameraSpec::Sim),
            ("aravis", None) => Ok(CameraSpec::Aravis(None)),
            ("aravis", Some(id)) if !id.is_empty() => Ok(CameraSpec::Aravis(Some(id.into()))),
            ("v4l", Some(dev)) if !dev.is_empty() => Ok(CameraSpec::V4l(dev.into())),
            _ => Err(CameraError::BadSpec {
                spec: s.into(),
                problem:
                    "expected `sim`, `aravis`, `aravis:ID`, `aravis:fake` or `v4l:/dev/videoN`"
                        .into(),
            }),
        }
    }
}

impl CameraSpec {
    /// Whether this camera looks at a simulated station (and so needs a
    /// [`SimulatedCamera`] and a [`crate::sim::ScreenState`]).
    pub fn is_simulated(&self) -> bool {
        matches!(self, CameraSpec::Sim)
            || matches!(self, CameraSpec::Aravis(Some(id)) if id == "fake")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse() {
        assert_eq!("sim".parse::<CameraSpec>().unwrap(), CameraSpec::Sim);
        assert_eq!(
            "aravis".parse::<CameraSpec>().unwrap(),
            CameraSpec::Aravis(None)
        );
        assert_eq!(
            "aravis:Baumer-0815".parse::<CameraSpec>().unwrap(),
            CameraSpec::Aravis(Some("Baumer-0815".into()))
        );
        assert_eq!(
            "v4l:/dev/video0".parse::<CameraSpec>().unwrap(),
            CameraSpec::V4l("/dev/video0".into())
        );
        for bad in ["", "v4l", "v4l:", "aravis:", "usb", "sim:x"] {
            let err = bad.parse::<CameraSpec>().unwrap_err();
            assert!(matches!(err, CameraError::BadSpec { .. }), "{bad}: {err}");
        }
        assert!("aravis:fake".parse::<CameraSpec>().unwrap().is_simulated());
        assert!(!"aravis:X".parse::<CameraSpec>().unwrap().is_simulated());
    }
}
