//! Video4Linux2 cameras (feature `v4l`): `GREY`, `Y16` and `YUYV` (luma),
//! exposure and gain through the standard controls, a memory-mapped stream
//! of driver buffers. V4L2 has no software trigger: the camera runs free
//! and the sequencer picks frames by timestamp.
//!
//! Timestamps: the driver's `CLOCK_MONOTONIC` buffer time (start or end of
//! frame, depending on the driver) minus the exposure time and one frame
//! interval (readout), mapped to [`Instant`]: not later than the true start
//! of the exposure for a camera that keeps up with its frame rate.
//!
//! Conversions and control mappings live in [`super::convert`] and are
//! tested without this feature. No V4L2 device exists on the machines the
//! tests run on, so this file is compiled and linted, not exercised.

use std::time::{Duration, Instant};

use v4l::buffer::Type;
use v4l::control::{Control, Value};
use v4l::io::mmap::Stream;
use v4l::io::traits::{CaptureStream, Stream as StreamTrait};
use v4l::video::Capture;
use v4l::{Device, Format, FourCC};

use super::convert::{self, ControlRange, Layout};
use super::{Camera, CameraConfig, CameraError, CameraInfo, Frame, PixelFormat, TriggerMode};

const CID_EXPOSURE_AUTO: u32 = 0x009a_0901;
const CID_EXPOSURE_ABSOLUTE: u32 = 0x009a_0902;
const CID_GAIN: u32 = 0x0098_0913;
/// `V4L2_EXPOSURE_MANUAL`.
const EXPOSURE_MANUAL: i64 = 1;

/// A V4L2 capture device.
pub struct V4lCamera {
    path: String,
    device: Device,
    stream: Option<Stream<'static>>,
    format: Format,
    model: String,
    /// Exposure time plus one frame interval, subtracted from the driver's
    /// timestamps.
    exposure: Duration,
    buffers: u32,
    scratch: Vec<u16>,
}

fn io_err(path: &str, what: &str, e: &std::io::Error) -> CameraError {
    if e.raw_os_error() == Some(19) {
        // ENODEV: unplugged.
        return CameraError::Disconnected {
            device: path.into(),
            problem: format!("{what}: {e}"),
        };
    }
    CameraError::Device {
        device: path.into(),
        problem: format!("{what}: {e}"),
    }
}

/// `CLOCK_MONOTONIC` now, ns.
fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

impl V4lCamera {
    /// Opens `path` (`/dev/videoN`).
    ///
    /// # Errors
    /// [`CameraError::Device`] when it cannot be opened or is no capture device.
    pub fn open(path: &str) -> Result<Self, CameraError> {
        let device = Device::with_path(path).map_err(|e| io_err(path, "open", &e))?;
        let caps = device
            .query_caps()
            .map_err(|e| io_err(path, "query capabilities", &e))?;
        let format = device
            .format()
            .map_err(|e| io_err(path, "get format", &e))?;
        Ok(V4lCamera {
            path: path.into(),
            device,
            stream: None,
            format,
            model: format!("{} ({})", caps.card, caps.driver),
            exposure: Duration::ZERO,
            buffers: 4,
            scratch: Vec::new(),
        })
    }

    fn range(&self, id: u32) -> Option<ControlRange> {
        let controls = self.device.query_controls().ok()?;
        let d = controls.into_iter().find(|c| c.id == id)?;
        Some(ControlRange {
            min: d.minimum,
            max: d.maximum,
            step: d.step.max(1) as i64,
            default: d.default,
        })
    }

    fn set(&self, field: &'static str, id: u32, value: i64) -> Result<(), CameraError> {
        self.device
            .set_control(Control {
                id,
                value: Value::Integer(value),
            })
            .map_err(|e| CameraError::Config {
                device: self.path.clone(),
                field,
                problem: e.to_string(),
            })
    }

    fn set_format(&mut self, wanted: Option<PixelFormat>) -> Result<(), CameraError> {
        let fourccs: &[&[u8; 4]] = match wanted {
            Some(PixelFormat::Mono8) => &[b"GREY"],
            Some(PixelFormat::Mono12 | PixelFormat::Mono16) => &[b"Y16 "],
            None => &[b"Y16 ", b"GREY", b"YUYV"],
        };
        for cc in fourccs {
            let want = Format::new(self.format.width, self.format.height, FourCC::new(cc));
            if let Ok(got) = self.device.set_format(&want) {
                if got.fourcc == want.fourcc {
                    self.format = got;
                    return Ok(());
                }
            }
        }
        Err(CameraError::Config {
            device: self.path.clone(),
            field: "pixel_format",
            problem: format!(
                "the device offers none of {fourccs:?} (see `v4l2-ctl --list-formats`)"
            ),
        })
    }

    fn convert(&mut self, bytes: &[u8]) -> Result<u8, String> {
        let layout = Layout {
            width: self.format.width as usize,
            height: self.format.height as usize,
            stride: self.format.stride as usize,
        };
        let out = &mut self.scratch;
        match &self.format.fourcc.repr {
            b"GREY" => convert::mono8(bytes, layout, out).map(|()| 8),
            b"Y16 " => convert::mono16le(bytes, layout, out).map(|()| 16),
            b"YUYV" => convert::yuyv_luma(bytes, layout, out).map(|()| 8),
            other => return Err(format!("unsupported format {other:?}")),
        }
        .map_err(|e| e.to_string())
    }
}

impl Camera for V4lCamera {
    fn describe(&self) -> CameraInfo {
        let res = (self.format.width, self.format.height);
        CameraInfo {
            backend: "v4l",
            id: self.path.clone(),
            model: self.model.clone(),
            sensor: res,
            resolution: res,
            pixel_formats: vec![PixelFormat::Mono8, PixelFormat::Mono16],
            software_trigger: false,
        }
    }

    fn configure(&mut self, config: &CameraConfig) -> Result<(), CameraError> {
        let path = self.path.clone();
        let unsupported = |field, problem: &str| CameraError::Config {
            device: path.clone(),
            field,
            problem: problem.into(),
        };
        if config.trigger == TriggerMode::Software {
            return Err(unsupported(
                "trigger",
                "V4L2 has no software trigger; use free running",
            ));
        }
        self.exposure = Duration::ZERO;
        if let Some(r) = config.region {
            if (r.x, r.y) != (0, 0) {
                return Err(unsupported(
                    "region",
                    "V4L2 capture has no offset; set only a size",
                ));
            }
            self.format.width = r.width;
            self.format.height = r.height;
        }
        self.set_format(config.pixel_format)?;
        if let Some(us) = config.exposure_us {
            let range = self.range(CID_EXPOSURE_ABSOLUTE);
            let range = range.ok_or_else(|| unsupported("exposure_us", "no exposure control"))?;
            let value = convert::v4l2_exposure(us, range)
                .map_err(|e| unsupported("exposure_us", &e.to_string()))?;
            self.set("exposure_us", CID_EXPOSURE_AUTO, EXPOSURE_MANUAL)?;
            self.set("exposure_us", CID_EXPOSURE_ABSOLUTE, value)?;
            self.exposure = Duration::from_micros(value as u64 * 100);
        }
        if let Some(db) = config.gain_db {
            let range = self
                .range(CID_GAIN)
                .ok_or_else(|| unsupported("gain_db", "no gain control"))?;
            let value = convert::v4l2_gain(db, range)
                .map_err(|e| unsupported("gain_db", &e.to_string()))?;
            self.set("gain_db", CID_GAIN, value)?;
        }
        self.buffers = config.buffers.clamp(2, 32) as u32;
        if let Ok(p) = self.device.params() {
            let (num, den) = (p.interval.numerator, p.interval.denominator);
            if den > 0 {
                self.exposure += Duration::from_secs_f64(f64::from(num) / f64::from(den));
            }
        }
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        let stream = Stream::with_buffers(&self.device, Type::VideoCapture, self.buffers)
            .map_err(|e| io_err(&self.path, "map buffers", &e))?;
        self.stream = Some(stream);
        Ok(())
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        let Some(mut stream) = self.stream.take() else {
            return Ok(());
        };
        let stopped =
            StreamTrait::stop(&mut stream).map_err(|e| io_err(&self.path, "stream off", &e));
        // v4l's `Drop` for a stream panics when turning streaming off fails
        // (other than for an unplugged device): keep that out of our drop.
        let dropped = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| drop(stream)));
        if dropped.is_err() {
            log::warn!("{}: releasing the capture buffers failed", self.path);
        }
        stopped
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        let path = self.path.clone();
        let Some(stream) = self.stream.as_mut() else {
            return Err(CameraError::Device {
                device: path,
                problem: "not streaming: call start() first".into(),
            });
        };
        stream.set_timeout(timeout.max(Duration::from_millis(1)));
        let (bytes, meta) = match stream.next() {
            Ok(x) => x,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                return Err(CameraError::Timeout {
                    device: path,
                    waited: timeout,
                })
            }
            Err(e) => return Err(io_err(&path, "dequeue", &e)),
        };
        let bytes = bytes[..(meta.bytesused as usize).min(bytes.len())].to_vec();
        let (sequence, stamp) = (u64::from(meta.sequence), meta.timestamp);
        let stamp_ns = stamp.sec as u64 * 1_000_000_000 + stamp.usec as u64 * 1000;
        let (now, now_ns) = (Instant::now(), monotonic_ns());
        let received = now
            .checked_sub(Duration::from_nanos(now_ns.saturating_sub(stamp_ns)))
            .unwrap_or(now);
        let bit_depth = self
            .convert(&bytes)
            .map_err(|problem| CameraError::BadFrame {
                device: path,
                sequence,
                problem,
            })?;
        Ok(Frame {
            data: std::mem::take(&mut self.scratch),
            width: self.format.width,
            height: self.format.height,
            bit_depth,
            timestamp: received.checked_sub(self.exposure).unwrap_or(received),
            sequence,
            exposed_pattern: None,
        })
    }
}

impl Drop for V4lCamera {
    fn drop(&mut self) {
        if let Err(e) = self.stop() {
            log::warn!("stopping the camera stream: {e}");
        }
    }
}
