//! The window, its wgpu surface and the fringe pipeline: what draws and
//! presents one pattern on a monitor.

use std::sync::Arc;
use std::time::{Duration, Instant};

use winit::event_loop::{ActiveEventLoop, OwnedDisplayHandle};
use winit::window::{Fullscreen, Window};

use crate::acquire::display::levels::Shading;
use crate::acquire::display::render::{open_device, scoped, wait_idle, FringePipeline};
use crate::acquire::display::{DisplayError, Shown};
use crate::acquire::patterns::Pattern;

use super::WindowConfig;

/// Surface formats that carry 8-bit levels unchanged (no sRGB transfer),
/// in order of preference.
const LEVEL_FORMATS: [wgpu::TextureFormat; 2] = [
    wgpu::TextureFormat::Bgra8Unorm,
    wgpu::TextureFormat::Rgba8Unorm,
];

/// A borderless window covering one monitor, with its surface.
pub(crate) struct Screen {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    surface_config: wgpu::SurfaceConfiguration,
    pipeline: FringePipeline,
    name: String,
    monitor_size: (u32, u32),
    shading: Shading,
    settle: Duration,
}

fn unavailable(display: &str, problem: String) -> DisplayError {
    DisplayError::Unavailable {
        display: display.to_string(),
        problem,
    }
}

impl Screen {
    /// Opens the window on monitor `config.monitor`, sized and placed to
    /// cover it, and a Fifo surface of a non-sRGB 8-bit format.
    ///
    /// # Errors
    /// [`DisplayError::Unavailable`] naming the monitor and the problem.
    pub(crate) fn open(
        event_loop: &ActiveEventLoop,
        config: &WindowConfig,
        display_handle: OwnedDisplayHandle,
    ) -> Result<Self, DisplayError> {
        let count = event_loop.available_monitors().count();
        let name = format!("monitor {}", config.monitor);
        let monitor = event_loop
            .available_monitors()
            .nth(config.monitor)
            .ok_or_else(|| unavailable(&name, format!("no such monitor ({count} found)")))?;
        let (size, position) = (monitor.size(), monitor.position());
        let monitor_size = (size.width, size.height);
        if let Some(expect) = config.expect_resolution.filter(|&e| e != monitor_size) {
            return Err(unavailable(
                &name,
                format!(
                    "resolution {}x{}, but the display profile says {}x{}",
                    size.width, size.height, expect.0, expect.1
                ),
            ));
        }
        // Without a window manager fullscreen is only a hint: size and place
        // the window on the monitor explicitly as well.
        let attributes = Window::default_attributes()
            .with_title("mfd fringes")
            .with_decorations(false)
            .with_inner_size(size)
            .with_position(position)
            .with_fullscreen(Some(Fullscreen::Borderless(Some(monitor))));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| unavailable(&name, format!("cannot open a window: {e}")))?,
        );
        window.set_cursor_visible(false);
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(display_handle)),
        );
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| unavailable(&name, format!("cannot create a surface: {e}")))?;
        let (adapter, device, queue) = open_device(&instance, Some(&surface), &name)?;
        let surface_config = surface_config(&surface, &adapter, window.inner_size(), &name)?;
        surface.configure(&device, &surface_config);
        let pipeline = FringePipeline::new(&device, surface_config.format);
        Ok(Screen {
            window,
            surface,
            device,
            queue,
            surface_config,
            pipeline,
            name,
            monitor_size,
            shading: config.shading,
            settle: config.settle,
        })
    }

    /// The monitor's resolution, which the patterns are drawn for.
    pub(crate) fn size(&self) -> (u32, u32) {
        self.monitor_size
    }

    /// Why the window does not exactly cover the monitor, if it does not.
    pub(crate) fn misfit(&self) -> Option<String> {
        let inner = self.window.inner_size();
        let surface = (self.surface_config.width, self.surface_config.height);
        if (inner.width, inner.height) == self.monitor_size && surface == self.monitor_size {
            return None;
        }
        Some(format!(
            "the window is {}x{} (surface {}x{}) but the monitor is {}x{}: the window \
             manager did not let it cover the monitor",
            inner.width,
            inner.height,
            surface.0,
            surface.1,
            self.monitor_size.0,
            self.monitor_size.1
        ))
    }

    /// Reconfigures the surface after the window was resized.
    pub(crate) fn resize(&mut self, width: u32, height: u32) {
        if width == 0 || height == 0 {
            return;
        }
        self.surface_config.width = width;
        self.surface_config.height = height;
        self.surface.configure(&self.device, &self.surface_config);
        self.window.request_redraw();
    }

    /// Draws `pattern`, waits for the GPU, presents; `presented` is taken
    /// right after `queue.present`.
    ///
    /// # Errors
    /// [`DisplayError::Unavailable`] if the window does not cover the monitor;
    /// [`DisplayError::Render`] if drawing or presenting fails.
    pub(crate) fn show(&mut self, index: usize, pattern: &Pattern) -> Result<Shown, DisplayError> {
        if let Some(problem) = self.misfit() {
            return Err(unavailable(&self.name, problem));
        }
        let frame = self.acquire(index)?;
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        scoped(&self.device, index, || {
            let mut encoder = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            self.pipeline.encode(
                &self.queue,
                &mut encoder,
                &view,
                pattern,
                self.monitor_size,
                &self.shading,
            );
            self.queue.submit([encoder.finish()]);
        })?;
        wait_idle(&self.device, index)?;
        self.window.pre_present_notify();
        self.queue.present(frame);
        let presented = Instant::now();
        Ok(Shown {
            index,
            pattern: *pattern,
            presented,
            settled: presented + self.settle,
        })
    }

    /// The next surface texture, reconfiguring once if the surface is
    /// outdated or lost.
    fn acquire(&mut self, index: usize) -> Result<wgpu::SurfaceTexture, DisplayError> {
        for _ in 0..2 {
            match self.surface.get_current_texture() {
                wgpu::CurrentSurfaceTexture::Success(frame)
                | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => return Ok(frame),
                wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                    self.surface.configure(&self.device, &self.surface_config);
                }
                other => {
                    return Err(DisplayError::Render {
                        index,
                        problem: format!("no surface texture to draw into: {other:?}"),
                    })
                }
            }
        }
        Err(DisplayError::Render {
            index,
            problem: "the surface stayed outdated after reconfiguring it".into(),
        })
    }
}

/// A Fifo configuration of a non-sRGB 8-bit format for `surface`.
fn surface_config(
    surface: &wgpu::Surface<'_>,
    adapter: &wgpu::Adapter,
    size: winit::dpi::PhysicalSize<u32>,
    name: &str,
) -> Result<wgpu::SurfaceConfiguration, DisplayError> {
    let caps = surface.get_capabilities(adapter);
    let format = LEVEL_FORMATS
        .into_iter()
        .find(|f| caps.formats.contains(f))
        .ok_or_else(|| {
            unavailable(
                name,
                format!(
                    "no non-sRGB 8-bit surface format (offered: {:?})",
                    caps.formats
                ),
            )
        })?;
    let mut config = surface
        .get_default_config(adapter, size.width, size.height)
        .ok_or_else(|| unavailable(name, "the adapter cannot present to this window".into()))?;
    config.format = format;
    config.present_mode = wgpu::PresentMode::Fifo;
    Ok(config)
}
