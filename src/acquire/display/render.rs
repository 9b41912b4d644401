//! The GPU side shared by the offscreen and window backends: opening an
//! adapter and device with errors that say what to install, and the fringe
//! pipeline (`fringe.wgsl`) that draws one [`Pattern`] into a target.

use std::f64::consts::TAU;

use crate::acquire::patterns::{FringeAxis, Pattern};

use super::levels::{Dither, Shading};
use super::DisplayError;

/// What to install when no adapter is found (Debian/Ubuntu package names).
pub const DRIVER_HINT: &str = "install a Vulkan driver (Debian/Ubuntu: `apt-get install \
     mesa-vulkan-drivers`, which brings the lavapipe CPU renderer) or a GPU driver";

/// Opens the default adapter (compatible with `surface` when given) and a
/// device on it. Uncaptured device errors are printed, not panicked on; the
/// render paths catch theirs with [`scoped`].
///
/// # Errors
/// [`DisplayError::Unavailable`] naming `display` and what to install.
pub(crate) fn open_device(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface<'_>>,
    display: &str,
) -> Result<(wgpu::Adapter, wgpu::Device, wgpu::Queue), DisplayError> {
    let unavailable = |problem: String| DisplayError::Unavailable {
        display: display.to_string(),
        problem,
    };
    let options = wgpu::RequestAdapterOptions {
        compatible_surface: surface,
        ..Default::default()
    };
    let adapter = pollster::block_on(instance.request_adapter(&options))
        .map_err(|e| unavailable(format!("no GPU adapter ({e}); {DRIVER_HINT}")))?;
    let desc = wgpu::DeviceDescriptor {
        label: Some("mfd display"),
        required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
        ..Default::default()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&desc)).map_err(|e| {
        let info = adapter.get_info();
        unavailable(format!("adapter `{}` gave no device: {e}", info.name))
    })?;
    device.on_uncaptured_error(std::sync::Arc::new(|e| {
        log::error!("mfd display: uncaptured GPU error: {e}");
    }));
    Ok((adapter, device, queue))
}

/// Runs `f` inside a validation and out-of-memory error scope and turns a
/// caught error into [`DisplayError::Render`] for pattern `index`.
///
/// # Errors
/// [`DisplayError::Render`] with the device's message.
pub(crate) fn scoped<T>(
    device: &wgpu::Device,
    index: usize,
    f: impl FnOnce() -> T,
) -> Result<T, DisplayError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let caught = pollster::block_on(validation.pop()).or(pollster::block_on(oom.pop()));
    match caught {
        None => Ok(out),
        Some(e) => Err(DisplayError::Render {
            index,
            problem: e.to_string(),
        }),
    }
}

/// Waits until the device has finished all submitted work.
///
/// # Errors
/// [`DisplayError::Render`] when the device is lost or the wait fails.
pub(crate) fn wait_idle(device: &wgpu::Device, index: usize) -> Result<(), DisplayError> {
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map(|_| ())
        .map_err(|e| DisplayError::Render {
            index,
            problem: format!("waiting for the GPU: {e}"),
        })
}

/// Size of the shader's uniform block (`Fringe` in `fringe.wgsl`), bytes.
const UNIFORM_BYTES: usize = 32;

/// The shader's uniform block for `pattern` on a `width × height` target:
/// the phase in cycles as `a·u + b·v + c` (from [`FringeAxis`], in `f64`,
/// with `c` reduced modulo 1 before the cast to `f32`), `2/γ`, the dither.
pub(crate) fn uniform_bytes(
    pattern: &Pattern,
    width: u32,
    height: u32,
    shading: &Shading,
) -> [u8; UNIFORM_BYTES] {
    let axis = FringeAxis::new(pattern.direction_deg, width, height);
    let (ds_du, ds_dv) = axis.gradient();
    let a = pattern.tau * ds_du;
    let b = pattern.tau * ds_dv;
    let c = (pattern.tau * axis.s(0.0, 0.0) + pattern.phase_rad / TAU).rem_euclid(1.0);
    let floats = [a as f32, b as f32, c as f32, (2.0 / shading.gamma) as f32];
    let dither: u32 = match shading.dither {
        Dither::None => 0,
        Dither::Bayer8 => 1,
    };
    let mut out = [0u8; UNIFORM_BYTES];
    for (k, v) in floats.iter().enumerate() {
        out[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    out[16..20].copy_from_slice(&dither.to_le_bytes());
    out
}

/// The fringe render pipeline for one target format.
pub(crate) struct FringePipeline {
    pipeline: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl FringePipeline {
    /// Compiles `fringe.wgsl` for targets of `format` (a non-sRGB format:
    /// the shader writes levels, not linear light).
    pub(crate) fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("fringe.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("fringe.wgsl").into()),
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("fringe"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState::from(format))],
            }),
            multiview_mask: None,
            cache: None,
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fringe uniform"),
            size: UNIFORM_BYTES as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fringe"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        FringePipeline {
            pipeline,
            uniform,
            bind_group,
        }
    }

    /// Records the drawing of `pattern` into `target` (`width × height`,
    /// the screen) on `encoder`; the uniform is written through `queue`, so
    /// submit `encoder` before drawing the next pattern.
    pub(crate) fn encode(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        pattern: &Pattern,
        (width, height): (u32, u32),
        shading: &Shading,
    ) {
        queue.write_buffer(
            &self.uniform,
            0,
            &uniform_bytes(pattern, width, height, shading),
        );
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("fringe"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
