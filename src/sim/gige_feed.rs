//! The frame feed of the fake GigE Vision camera: what the simulated
//! station's camera would record, or what it would see of a calibration
//! target, rendered into the buffers that the fake camera sends over
//! loopback.
//!
//! The Aravis plumbing (the fake camera, its fill callback, the client) is
//! [`crate::sim::aravis_fake`] (feature `aravis`); this part needs no
//! Aravis and renders with a [`SimulatedCamera`] looking at its
//! [`ScreenState`], or with a [`SpotCamera`] looking at a point target.

use std::sync::Mutex;
use std::time::Instant;

use super::camera::SimulatedCamera;
use super::screen::ScreenState;
use super::target::SpotCamera;
use crate::acquire::camera::{Camera, PixelFormat};

/// A rendered frame's tag: the schedule index of the pattern it saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Filled {
    /// Pattern on the screen at the exposure; `None` while it was blank.
    pub exposed_pattern: Option<usize>,
}

/// What a feed renders.
#[derive(Debug)]
enum Source {
    /// The station's camera looking at the screen through the element.
    Station(Box<SimulatedCamera>),
    /// The camera looking at a calibration target's spot.
    Target(SpotCamera),
}

/// Renders the simulated station, or a target, into the fake camera's
/// frame buffers.
#[derive(Debug)]
pub struct GigeFeed {
    source: Mutex<Source>,
    screen: Option<ScreenState>,
    resolution: (u32, u32),
    format: PixelFormat,
}

/// 8 bits for an 8-bit simulation, 16 otherwise.
fn wire_format(info: &crate::acquire::camera::CameraInfo) -> PixelFormat {
    match info.pixel_formats.first() {
        Some(PixelFormat::Mono8) => PixelFormat::Mono8,
        _ => PixelFormat::Mono16,
    }
}

impl GigeFeed {
    /// A feed rendering with `camera` (and the screen it looks at).
    pub fn new(camera: SimulatedCamera) -> Self {
        let screen = camera.screen().clone();
        let info = camera.describe();
        GigeFeed {
            source: Mutex::new(Source::Station(Box::new(camera))),
            screen: Some(screen),
            resolution: info.resolution,
            format: wire_format(&info),
        }
    }

    /// A feed of `camera`'s target frames (`mfd calibrate capture --camera
    /// aravis:fake`), each with fresh noise.
    pub fn target(camera: SpotCamera) -> Self {
        let info = camera.describe();
        GigeFeed {
            source: Mutex::new(Source::Target(camera)),
            screen: None,
            resolution: info.resolution,
            format: wire_format(&info),
        }
    }

    /// The screen the simulated camera looks at; `None` for a target.
    pub fn screen(&self) -> Option<&ScreenState> {
        self.screen.as_ref()
    }

    /// Frame size `(width, height)`, pixels.
    pub fn resolution(&self) -> (u32, u32) {
        self.resolution
    }

    /// The format the fake camera should send: 8 bits for an 8-bit
    /// simulation, 16 otherwise.
    pub fn pixel_format(&self) -> PixelFormat {
        self.format
    }

    /// Renders the screen as it is now into `bytes`, a `width × height`
    /// buffer of `format` (8-bit samples, or 16-bit little-endian), for
    /// frame `frame_id`. Returns `None` and writes nothing when the buffer
    /// is not the station's size (the client has not set the region yet),
    /// too short, or of another format.
    pub fn fill(
        &self,
        bytes: &mut [u8],
        width: usize,
        height: usize,
        frame_id: u64,
        format: PixelFormat,
    ) -> Option<Filled> {
        let now = Instant::now();
        let mut source = self.source.lock().unwrap_or_else(|p| p.into_inner());
        let (data, exposed_pattern) = match &mut *source {
            Source::Station(cam) => {
                let frame = cam.render_at(now, frame_id);
                (frame.data, frame.exposed_pattern)
            }
            Source::Target(cam) => (cam.render(), None),
        };
        drop(source);
        let n = width * height;
        if self.resolution != (width as u32, height as u32) || data.len() != n {
            return None;
        }
        match format {
            PixelFormat::Mono8 if bytes.len() >= n => {
                for (b, &v) in bytes.iter_mut().zip(&data) {
                    *b = v.min(255) as u8;
                }
            }
            PixelFormat::Mono16 if bytes.len() >= 2 * n => {
                for (b, &v) in bytes.chunks_exact_mut(2).zip(&data) {
                    b.copy_from_slice(&v.to_le_bytes());
                }
            }
            _ => return None,
        }
        Some(Filled { exposed_pattern })
    }
}
