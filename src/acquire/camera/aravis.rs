//! GigE Vision and USB3 Vision cameras through libaravis 0.8 (feature
//! `aravis`).
//!
//! Frames are copied out of a pool of driver buffers that is refilled as
//! frames are taken. Mono8, Mono12 (unpacked, in 16 bits) and Mono16.
//! Timestamps: the host time at which the frame's first packet arrived
//! (`arv_buffer_get_system_timestamp`, wall clock, mapped to [`Instant`])
//! minus a *lead*: the exposure time, and when free running one frame
//! period more. A camera that sustains its frame rate reads out and sends a
//! frame within a period of the end of its exposure, so the estimate is not
//! later than the true start of the exposure and a frame the sequencer
//! accepts was exposed after the settle point. Triggered, the exposure
//! follows the trigger (sent after the settle point), so only the exposure
//! time is subtracted.
//!
//! The stream's statistics (completed buffers, failures, underruns, and for
//! GigE Vision resent and missing packets) are read with
//! [`AravisCamera::statistics`].

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use aravis::glib;
use aravis::glib::prelude::Cast;
use aravis::prelude::*;
use aravis::{Buffer, BufferStatus, GvStream, GvStreamOption, GvStreamSocketBuffer, Stream};

use super::convert::{self, FrameIdUnwrap, Layout};
use super::{
    Camera, CameraConfig, CameraError, CameraInfo, Frame, PixelFormat, StreamStatistics,
    TriggerMode,
};

/// Pattern tags of an in-process fake camera: `(GVSP frame id, pattern)`.
pub(crate) type Tags = Arc<Mutex<VecDeque<(u64, Option<usize>)>>>;

/// Maps the wall clock to [`Instant`] (taken once; drift over a
/// measurement is far below a frame period).
#[derive(Debug, Clone, Copy)]
struct HostClock {
    instant: Instant,
    wall_ns: u64,
}

impl HostClock {
    fn now() -> Self {
        let wall_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        HostClock {
            instant: Instant::now(),
            wall_ns,
        }
    }

    fn instant(&self, wall_ns: u64) -> Instant {
        if wall_ns >= self.wall_ns {
            self.instant + Duration::from_nanos(wall_ns - self.wall_ns)
        } else {
            let back = Duration::from_nanos(self.wall_ns - wall_ns);
            self.instant.checked_sub(back).unwrap_or(self.instant)
        }
    }
}

/// A camera driven by libaravis.
pub struct AravisCamera {
    camera: aravis::Camera,
    stream: Option<Stream>,
    info: CameraInfo,
    /// Subtracted from the arrival time (see the module docs).
    lead: Duration,
    buffers: usize,
    lost: Arc<AtomicBool>,
    clock: HostClock,
    frame_ids: FrameIdUnwrap,
    tags: Option<Tags>,
    scratch: Vec<u16>,
    last_statistics: StreamStatistics,
}

fn device_err(device: &str, e: &glib::Error) -> CameraError {
    CameraError::Device {
        device: device.into(),
        problem: e.to_string(),
    }
}

fn format_of(f: aravis::PixelFormat) -> Option<PixelFormat> {
    match f {
        aravis::PixelFormat::MONO_8 => Some(PixelFormat::Mono8),
        aravis::PixelFormat::MONO_12 => Some(PixelFormat::Mono12),
        aravis::PixelFormat::MONO_16 => Some(PixelFormat::Mono16),
        _ => None,
    }
}

fn aravis_format(f: PixelFormat) -> aravis::PixelFormat {
    match f {
        PixelFormat::Mono8 => aravis::PixelFormat::MONO_8,
        PixelFormat::Mono12 => aravis::PixelFormat::MONO_12,
        PixelFormat::Mono16 => aravis::PixelFormat::MONO_16,
    }
}

impl AravisCamera {
    /// Opens the camera with Aravis ID `id` (as `arv-tool-0.8` lists it, or
    /// an IP address), or the first one found.
    ///
    /// # Errors
    /// [`CameraError::Device`] when no such camera answers.
    pub fn open(id: Option<&str>) -> Result<Self, CameraError> {
        let name = id.unwrap_or("first Aravis camera").to_string();
        let camera = aravis::Camera::new(id).map_err(|e| CameraError::Device {
            device: name.clone(),
            problem: format!("{e} (list cameras with `arv-tool-0.8`)"),
        })?;
        let lost = Arc::new(AtomicBool::new(false));
        if let Some(device) = camera.device() {
            let flag = Arc::clone(&lost);
            device.connect_control_lost(move |_| flag.store(true, Ordering::SeqCst));
        }
        if camera.is_gv_device() {
            // Without the packet socket and with a buffer sized to the
            // payload, no packets are lost on loopback or a busy host.
            camera.gv_set_stream_options(GvStreamOption::PACKET_SOCKET_DISABLED);
        }
        let info = describe(&camera, &name)?;
        Ok(AravisCamera {
            camera,
            stream: None,
            info,
            lead: Duration::ZERO,
            buffers: 8,
            lost,
            clock: HostClock::now(),
            frame_ids: FrameIdUnwrap::default(),
            tags: None,
            scratch: Vec::new(),
            last_statistics: StreamStatistics::default(),
        })
    }

    /// The stream's statistics since [`Camera::start`] (after
    /// [`Camera::stop`]: those of the last stream).
    pub fn statistics(&self) -> StreamStatistics {
        let Some(stream) = &self.stream else {
            return self.last_statistics;
        };
        let (completed, failures, underruns) = stream.statistics();
        let (resent_packets, missing_packets) = stream
            .downcast_ref::<GvStream>()
            .map_or((0, 0), |gv| gv.statistics());
        StreamStatistics {
            completed,
            failures,
            underruns,
            resent_packets,
            missing_packets,
        }
    }

    /// Looks up pattern tags (set by an in-process fake camera) by frame id.
    pub(crate) fn set_tags(&mut self, tags: Tags) {
        self.tags = Some(tags);
    }

    fn id(&self) -> &str {
        &self.info.id
    }

    fn frame_from(&mut self, buffer: &Buffer) -> Result<Frame, CameraError> {
        let raw_id = buffer.frame_id();
        let sequence = self.frame_ids.unwrap(raw_id);
        let bad = |problem: String| CameraError::BadFrame {
            device: self.info.id.clone(),
            sequence,
            problem,
        };
        if buffer.status() != BufferStatus::Success {
            return Err(bad(format!("buffer status {:?}", buffer.status())));
        }
        let format = buffer.image_pixel_format();
        let Some(pf) = format_of(format) else {
            return Err(bad(format!("unsupported pixel format {format:?}")));
        };
        let (w, h) = (
            buffer.image_width() as usize,
            buffer.image_height() as usize,
        );
        let layout = Layout {
            width: w,
            height: h,
            stride: 0,
        };
        let data = buffer.image_data();
        let converted = match pf {
            PixelFormat::Mono8 => convert::mono8(&data, layout, &mut self.scratch),
            PixelFormat::Mono12 | PixelFormat::Mono16 => {
                convert::mono16le(&data, layout, &mut self.scratch)
            }
        };
        converted.map_err(|e| bad(e.to_string()))?;
        let received = self.clock.instant(buffer.system_timestamp());
        let exposed_pattern = self.tags.as_ref().and_then(|tags| {
            let tags = tags.lock().unwrap_or_else(|p| p.into_inner());
            tags.iter()
                .rev()
                .find(|(id, _)| *id == raw_id)
                .and_then(|t| t.1)
        });
        Ok(Frame {
            data: std::mem::take(&mut self.scratch),
            width: w as u32,
            height: h as u32,
            bit_depth: pf.bit_depth(),
            timestamp: received.checked_sub(self.lead).unwrap_or(received),
            sequence,
            exposed_pattern,
        })
    }
}

fn describe(camera: &aravis::Camera, name: &str) -> Result<CameraInfo, CameraError> {
    let err = |e: glib::Error| device_err(name, &e);
    let vendor = camera.vendor_name().map_err(err)?;
    let model = camera.model_name().map_err(err)?;
    let id = camera
        .device_id()
        .map(|s| s.to_string())
        .unwrap_or(name.into());
    let sensor = camera.sensor_size().map_err(err)?;
    let (_, _, w, h) = camera.region().map_err(err)?;
    let pixel_formats = camera
        .dup_available_pixel_formats()
        .map_err(err)?
        .into_iter()
        .filter_map(|f| format_of(aravis::PixelFormat::from_raw(f as u32)))
        .collect();
    Ok(CameraInfo {
        backend: "aravis",
        id,
        model: format!("{vendor} {model}"),
        sensor: (sensor.0 as u32, sensor.1 as u32),
        resolution: (w as u32, h as u32),
        pixel_formats,
        software_trigger: camera.is_software_trigger_supported().is_ok(),
    })
}

impl Camera for AravisCamera {
    fn describe(&self) -> CameraInfo {
        self.info.clone()
    }

    fn configure(&mut self, config: &CameraConfig) -> Result<(), CameraError> {
        let id = self.info.id.clone();
        let cfg = |field: &'static str| {
            let id = id.clone();
            move |e: glib::Error| CameraError::Config {
                device: id,
                field,
                problem: e.to_string(),
            }
        };
        let cam = &self.camera;
        if let Some(f) = config.pixel_format {
            cam.set_pixel_format(aravis_format(f))
                .map_err(cfg("pixel_format"))?;
        }
        if let Some(r) = config.region {
            cam.set_region(r.x as i32, r.y as i32, r.width as i32, r.height as i32)
                .map_err(cfg("region"))?;
        }
        if let Some(us) = config.exposure_us {
            cam.set_exposure_time(us).map_err(cfg("exposure_us"))?;
        }
        if let Some(db) = config.gain_db {
            cam.set_gain(db).map_err(cfg("gain_db"))?;
        }
        match config.trigger {
            TriggerMode::Software => cam.set_trigger("Software").map_err(cfg("trigger"))?,
            TriggerMode::FreeRunning => {
                cam.clear_triggers().map_err(cfg("trigger"))?;
                if let Some(hz) = config.frame_rate_hz {
                    cam.set_frame_rate(hz).map_err(cfg("frame_rate_hz"))?;
                }
            }
        }
        let exposure_us = cam.exposure_time().map_err(cfg("exposure_us"))?;
        let period_s = match config.trigger {
            TriggerMode::Software => 0.0,
            TriggerMode::FreeRunning => {
                let hz = cam.frame_rate().map_err(cfg("frame_rate_hz"))?;
                if hz > 0.0 {
                    1.0 / hz
                } else {
                    0.0
                }
            }
        };
        self.lead = Duration::from_secs_f64(exposure_us.max(0.0) * 1e-6 + period_s);
        self.buffers = config.buffers.max(2);
        let (_, _, w, h) = cam.region().map_err(cfg("region"))?;
        self.info.resolution = (w as u32, h as u32);
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        let id = self.id().to_string();
        let stream = self
            .camera
            .create_stream()
            .map_err(|e| device_err(&id, &e))?;
        let payload = self.camera.payload().map_err(|e| device_err(&id, &e))?;
        if let Some(gv) = stream.downcast_ref::<GvStream>() {
            // Room for several frames: `Auto` sizes the socket buffer to one
            // payload, which small frames overflow (per-packet overhead)
            // whenever the receiving thread is late.
            gv.set_socket_buffer(GvStreamSocketBuffer::Fixed);
            gv.set_socket_buffer_size((payload as i32).saturating_mul(4).max(1 << 21));
        }
        for _ in 0..self.buffers {
            stream.push_buffer(Buffer::new_allocate(payload as usize));
        }
        self.clock = HostClock::now();
        self.camera
            .start_acquisition()
            .map_err(|e| device_err(&id, &e))?;
        self.stream = Some(stream);
        Ok(())
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.last_statistics = self.statistics();
        if self.stream.take().is_some() {
            let id = self.id().to_string();
            self.camera
                .stop_acquisition()
                .map_err(|e| device_err(&id, &e))?;
        }
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        let id = self.id().to_string();
        if self.lost.load(Ordering::SeqCst) {
            return Err(CameraError::Disconnected {
                device: id,
                problem: "control channel lost (no heartbeat answer)".into(),
            });
        }
        let Some(stream) = self.stream.clone() else {
            return Err(CameraError::Device {
                device: id,
                problem: "not streaming: call start() first".into(),
            });
        };
        let popped = if timeout.is_zero() {
            stream.try_pop_buffer()
        } else {
            stream.timeout_pop_buffer(timeout.as_micros() as u64)
        };
        let Some(buffer) = popped else {
            return Err(CameraError::Timeout {
                device: id,
                waited: timeout,
            });
        };
        let frame = self.frame_from(&buffer);
        stream.push_buffer(buffer);
        frame
    }

    fn stream_statistics(&self) -> Option<StreamStatistics> {
        Some(self.statistics())
    }

    fn trigger(&mut self) -> Result<(), CameraError> {
        let id = self.id().to_string();
        self.camera
            .software_trigger()
            .map_err(|e| device_err(&id, &e))
    }
}

impl Drop for AravisCamera {
    fn drop(&mut self) {
        if let Err(e) = self.stop() {
            log::warn!("stopping the camera stream: {e}");
        }
    }
}
