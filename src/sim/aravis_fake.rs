//! The simulated station served over the real GigE Vision protocol
//! (feature `aravis`): libaravis's fake GigE Vision camera runs in this
//! process on the loopback interface, its images filled by the simulated
//! station's feed ([`GigeFeed`], in `sim`), and an [`AravisCamera`] client
//! connects to it at `127.0.0.1` like to any camera on the network
//! (GVCP control, GVSP stream, heartbeats, packet resends).
//!
//! The fake camera streams freely at its frame rate (it does not honour
//! software triggers), so the sequencer picks frames by timestamp. The fill
//! callback notes which pattern each frame id saw; the client reports it as
//! [`Frame::exposed_pattern`], the sequence check of the simulated cameras.
//! One fake camera at a time per host: it binds the GVCP port 3956 on lo.

use std::collections::VecDeque;
use std::ffi::c_void;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use aravis::glib::translate::ToGlibPtr;
use aravis::GvFakeCamera;

use crate::acquire::camera::aravis::{AravisCamera, Tags};
use crate::acquire::camera::StreamStatistics;
use crate::acquire::camera::TriggerMode;
use crate::acquire::camera::{
    Camera, CameraConfig, CameraError, CameraInfo, Frame, PixelFormat, Region,
};
// The `aravis:fake` selection point: the one place this module reaches
// into the simulated station.
use super::{GigeFeed, ScreenState, SimulatedCamera, SpotCamera};

/// Tags kept (frames the client may still have queued).
const TAGS_KEPT: usize = 1024;

/// What the fill callback needs; boxed so its address is stable.
struct Fill {
    feed: GigeFeed,
    tags: Tags,
}

/// The fake camera's fill-pattern callback: renders the screen as it is now.
///
/// # Safety
/// `buffer` must be a valid `ArvBuffer` whose data holds `width · height`
/// samples of `pixel_format`, and `data` the `Fill` registered with it.
unsafe extern "C" fn fill_pattern(
    buffer: *mut aravis_sys::ArvBuffer,
    data: *mut c_void,
    _exposure_time_us: u32,
    _gain: u32,
    pixel_format: aravis_sys::ArvPixelFormat,
) {
    if buffer.is_null() || data.is_null() {
        return;
    }
    // SAFETY: `data` is the `Box<Fill>` registered in `FakeStation::start`;
    // `FakeStation::drop` unregisters the callback (under the fake camera's
    // fill mutex, so no call is in flight) before freeing it.
    let fill = unsafe { &*(data as *const Fill) };
    // SAFETY: `buffer` is the valid buffer the fake camera is filling.
    let (ptr, w, h, id) = unsafe {
        (
            aravis_sys::arv_buffer_get_data(buffer, std::ptr::null_mut()),
            aravis_sys::arv_buffer_get_image_width(buffer).max(0) as usize,
            aravis_sys::arv_buffer_get_image_height(buffer).max(0) as usize,
            aravis_sys::arv_buffer_get_frame_id(buffer),
        )
    };
    if ptr.is_null() {
        return;
    }
    // Bits per pixel are bits 16–23 of a GenICam pixel format code.
    let size = w * h * ((pixel_format >> 16) & 0xFF) as usize / 8;
    // SAFETY: `arv_fake_camera_fill_buffer` calls the fill pattern only for
    // a buffer allocated with at least the payload, `width · height ·
    // bits / 8` bytes (else it marks it SIZE_MISMATCH and returns); the
    // data size it reports is the received size, 0 on the sending side.
    let bytes = unsafe { std::slice::from_raw_parts_mut(ptr, size) };
    // A panic must not unwind into C.
    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        fill.render(bytes, w, h, id, pixel_format);
    }));
}

impl Fill {
    fn render(&self, bytes: &mut [u8], w: usize, h: usize, id: u64, format: u32) {
        let format = match format {
            aravis_sys::ARV_PIXEL_FORMAT_MONO_8 => PixelFormat::Mono8,
            aravis_sys::ARV_PIXEL_FORMAT_MONO_16 => PixelFormat::Mono16,
            _ => return,
        };
        let Some(filled) = self.feed.fill(bytes, w, h, id, format) else {
            return;
        };
        let mut tags = self.tags.lock().unwrap_or_else(|p| p.into_inner());
        if tags.len() == TAGS_KEPT {
            tags.pop_front();
        }
        tags.push_back((id, filled.exposed_pattern));
    }
}

/// A simulated station behind a GigE Vision fake camera on loopback, and
/// the Aravis client talking to it.
pub struct FakeStation {
    // Field order is drop order: the client goes first, then the server.
    client: AravisCamera,
    server: GvFakeCamera,
    fill: Box<Fill>,
    resolution: (u32, u32),
    format: PixelFormat,
}

impl FakeStation {
    /// Starts the fake camera on `lo`, serving `sim`'s frames, and connects.
    ///
    /// # Errors
    /// [`CameraError::Device`] when the fake camera cannot bind loopback
    /// (another one running?) or the client cannot reach it.
    pub fn start(sim: SimulatedCamera) -> Result<Self, CameraError> {
        Self::serve(GigeFeed::new(sim))
    }

    /// Starts the fake camera on `lo`, serving a calibration target's
    /// frames (`mfd calibrate capture --camera aravis:fake`), and connects.
    ///
    /// # Errors
    /// As [`FakeStation::start`].
    pub fn start_target(target: SpotCamera) -> Result<Self, CameraError> {
        Self::serve(GigeFeed::target(target))
    }

    /// Starts the fake camera on `lo`, serving `feed`, and connects.
    fn serve(feed: GigeFeed) -> Result<Self, CameraError> {
        let (w, h) = feed.resolution();
        let format = feed.pixel_format();
        let serial = format!("MFD{}", std::process::id());
        let server = GvFakeCamera::new(Some("lo"), Some(&serial));
        if !server.is_running() {
            return Err(CameraError::Device {
                device: "aravis:fake".into(),
                problem: "the GigE Vision fake camera could not bind 127.0.0.1:3956 \
                          (is another fake camera running?)"
                    .into(),
            });
        }
        let tags: Tags = Arc::new(Mutex::new(VecDeque::new()));
        let fill = Box::new(Fill {
            feed,
            tags: Arc::clone(&tags),
        });
        let Some(fake) = server.fake_camera() else {
            return Err(CameraError::Device {
                device: "aravis:fake".into(),
                problem: "the GigE Vision fake camera has no camera model".into(),
            });
        };
        // SAFETY: `fake` is a live ArvFakeCamera; the data pointer stays valid
        // until `Drop` unregisters the callback (see `fill_pattern`).
        unsafe {
            aravis_sys::arv_fake_camera_set_fill_pattern(
                fake.to_glib_none().0,
                Some(fill_pattern),
                &*fill as *const Fill as *mut c_void,
            );
        }
        let mut client = AravisCamera::open(Some("127.0.0.1"))?;
        client.set_tags(tags);
        Ok(FakeStation {
            client,
            server,
            fill,
            resolution: (w, h),
            format,
        })
    }

    /// The client's stream statistics.
    pub fn statistics(&self) -> StreamStatistics {
        self.client.statistics()
    }

    /// Makes the fake camera drop each GVSP packet with probability
    /// `ratio` (libaravis's unseeded `g_random`), to exercise incomplete
    /// frames over the real protocol. The fake camera does not answer
    /// packet-resend requests, so a frame that lost a packet stays
    /// incomplete.
    pub fn set_packet_loss(&self, ratio: f64) {
        self.server.set_gvsp_lost_ratio(ratio.clamp(0.0, 1.0));
    }

    /// The screen the simulated camera behind the fake looks at; `None`
    /// when it serves a target.
    pub fn screen(&self) -> Option<&ScreenState> {
        self.fill.feed.screen()
    }
}

impl Camera for FakeStation {
    fn describe(&self) -> CameraInfo {
        let mut info = self.client.describe();
        info.software_trigger = false;
        info
    }

    /// Sets the station's frame size and the simulation's bit depth, then
    /// `config` (which must ask for free running).
    fn configure(&mut self, config: &CameraConfig) -> Result<(), CameraError> {
        if config.trigger == TriggerMode::Software {
            return Err(CameraError::Config {
                device: "aravis:fake".into(),
                field: "trigger",
                problem: "the Aravis fake camera ignores software triggers; use free running"
                    .into(),
            });
        }
        let (width, height) = self.resolution;
        let config = CameraConfig {
            pixel_format: Some(self.format),
            region: Some(Region {
                x: 0,
                y: 0,
                width,
                height,
            }),
            ..config.clone()
        };
        self.client.configure(&config)
    }

    fn start(&mut self) -> Result<(), CameraError> {
        self.client.start()
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.client.stop()
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        self.client.next_frame(timeout)
    }

    fn stream_statistics(&self) -> Option<StreamStatistics> {
        Some(self.client.statistics())
    }
}

impl Drop for FakeStation {
    fn drop(&mut self) {
        if let Err(e) = self.client.stop() {
            log::warn!("stopping the fake camera's stream: {e}");
        }
        if let Some(fake) = self.server.fake_camera() {
            // SAFETY: resets the default fill pattern under the fake camera's
            // fill mutex: afterwards no call can reach `self.fill`.
            unsafe {
                aravis_sys::arv_fake_camera_set_fill_pattern(
                    fake.to_glib_none().0,
                    None,
                    std::ptr::null_mut(),
                );
            }
        }
    }
}
