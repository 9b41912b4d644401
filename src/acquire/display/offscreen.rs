//! The offscreen display: the fringe shader rendered into a texture of the
//! screen's size and read back on request. Always built; what tests, checks
//! (`mfd display --offscreen --png`) and the simulated station use.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use crate::acquire::patterns::Pattern;
use crate::optics::station::DisplayProfile;

use super::levels::{Dither, Shading};
use super::render::{open_device, scoped, wait_idle, FringePipeline};
use super::{DisplayError, PatternDisplay, Shown};

/// Texture format of the offscreen screen: one 8-bit level per pixel, no
/// sRGB transfer (the shader writes levels).
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;

/// A screen in GPU memory. `show` draws and waits for the GPU; `read_frame`
/// returns what is on it.
pub struct OffscreenDisplay {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: String,
    pipeline: FringePipeline,
    target: wgpu::Texture,
    view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row_bytes: u32,
    size: (u32, u32),
    shading: Shading,
    settle: Duration,
    /// Schedule index of the pattern on the screen (what errors of a
    /// readback name).
    last_index: usize,
}

impl OffscreenDisplay {
    /// A `width × height` offscreen screen with `shading`, whose patterns
    /// count as settled `settle` after the GPU finished them.
    ///
    /// # Errors
    /// [`DisplayError::Unavailable`] without a GPU adapter (names what to
    /// install); [`DisplayError::Invalid`] for a size the adapter cannot hold.
    pub fn new(
        width: u32,
        height: u32,
        shading: Shading,
        settle: Duration,
    ) -> Result<Self, DisplayError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let (adapter, device, queue) = open_device(&instance, None, "offscreen")?;
        let max = device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(DisplayError::Invalid {
                field: "resolution",
                problem: format!("{width}×{height}: expected 1 to {max} pixels a side"),
            });
        }
        let info = adapter.get_info();
        let target = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen screen"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = target.create_view(&wgpu::TextureViewDescriptor::default());
        let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let padded_row_bytes = width.div_ceil(align) * align;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("offscreen readback"),
            size: u64::from(padded_row_bytes) * u64::from(height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let pipeline = FringePipeline::new(&device, FORMAT);
        Ok(OffscreenDisplay {
            device,
            queue,
            adapter: format!("{} ({:?})", info.name, info.backend),
            pipeline,
            target,
            view,
            readback,
            padded_row_bytes,
            size: (width, height),
            shading,
            settle,
            last_index: 0,
        })
    }

    /// An offscreen screen of a display profile: its resolution, gamma and
    /// settle time.
    ///
    /// # Errors
    /// As [`OffscreenDisplay::new`]; [`DisplayError::Invalid`] for a bad
    /// gamma or settle time in the profile.
    pub fn from_profile(profile: &DisplayProfile, dither: Dither) -> Result<Self, DisplayError> {
        let shading = Shading::from_profile(profile, dither)?;
        let settle = settle_time(profile)?;
        let [w, h] = profile.resolution;
        OffscreenDisplay::new(w, h, shading, settle)
    }

    /// The adapter rendering, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)`.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// The intensity-to-level mapping in use.
    pub fn shading(&self) -> &Shading {
        &self.shading
    }

    /// Draws `pattern` and returns once the GPU has finished it, with the
    /// instant it did.
    ///
    /// # Errors
    /// [`DisplayError::Render`] when the device reports an error.
    pub fn draw(&mut self, index: usize, pattern: &Pattern) -> Result<Instant, DisplayError> {
        self.last_index = index;
        let submission = scoped(&self.device, index, || {
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            self.pipeline.encode(
                &self.queue,
                &mut encoder,
                &self.view,
                pattern,
                self.size,
                &self.shading,
            );
            self.queue.submit([encoder.finish()])
        })?;
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            })
            .map_err(|e| DisplayError::Render {
                index,
                problem: format!("waiting for the GPU: {e}"),
            })?;
        Ok(Instant::now())
    }

    /// What the screen shows now: one level per pixel, row-major,
    /// `width × height` bytes.
    ///
    /// # Errors
    /// [`DisplayError::Render`] naming the last drawn pattern when the copy
    /// or the mapping fails.
    pub fn read_frame(&self) -> Result<Vec<u8>, DisplayError> {
        let index = self.last_index;
        let fail = |problem: String| DisplayError::Render { index, problem };
        let (width, height) = self.size;
        scoped(&self.device, index, || {
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            encoder.copy_texture_to_buffer(
                self.target.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &self.readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(self.padded_row_bytes),
                        rows_per_image: Some(height),
                    },
                },
                self.target.size(),
            );
            self.queue.submit([encoder.finish()]);
        })?;
        let (tx, rx) = mpsc::channel();
        self.readback.map_async(wgpu::MapMode::Read, .., move |r| {
            // The receiver waits below; if it is gone there is no one to tell.
            let _ = tx.send(r);
        });
        wait_idle(&self.device, index)?;
        rx.recv()
            .map_err(|_| fail("readback: the map callback never ran".into()))?
            .map_err(|e| fail(format!("readback: {e}")))?;
        let mut out = Vec::with_capacity(width as usize * height as usize);
        {
            let mapped = self
                .readback
                .get_mapped_range(..)
                .map_err(|e| fail(format!("readback: {e}")))?;
            for row in mapped.chunks_exact(self.padded_row_bytes as usize) {
                out.extend_from_slice(&row[..width as usize]);
            }
        }
        self.readback.unmap();
        Ok(out)
    }

    /// Draws `pattern` and reads the frame back.
    ///
    /// # Errors
    /// As [`OffscreenDisplay::draw`] and [`OffscreenDisplay::read_frame`].
    pub fn render(&mut self, pattern: &Pattern) -> Result<Vec<u8>, DisplayError> {
        self.draw(0, pattern)?;
        self.read_frame()
    }
}

impl PatternDisplay for OffscreenDisplay {
    fn resolution(&self) -> (u32, u32) {
        self.size
    }

    /// `presented` is when the GPU finished the frame.
    fn show(&mut self, index: usize, pattern: &Pattern) -> Result<Shown, DisplayError> {
        let presented = self.draw(index, pattern)?;
        Ok(Shown {
            index,
            pattern: *pattern,
            presented,
            settled: presented + self.settle,
        })
    }
}

/// The settle time of a display profile.
///
/// # Errors
/// [`DisplayError::Invalid`] unless `settle_ms` is finite and ≥ 0.
pub fn settle_time(profile: &DisplayProfile) -> Result<Duration, DisplayError> {
    Duration::try_from_secs_f64(profile.settle_ms / 1000.0).map_err(|_| DisplayError::Invalid {
        field: "settle_ms",
        problem: format!("expected a finite time ≥ 0 ms, found {}", profile.settle_ms),
    })
}
