//! The devices of `mfd measure`: the display (`offscreen`, or a monitor's
//! fullscreen window with feature `display`) and the camera (simulated,
//! with its faults, or real) with its configuration.

use std::time::Duration;

#[cfg(feature = "display")]
use anyhow::Context;

use mfd::acquire::camera::{Camera, CameraConfig, CameraSpec, PixelFormat};
use mfd::acquire::display::{DisplayError, Dither, OffscreenDisplay, PatternDisplay, Shading};
use mfd::optics::station::{Station, Wedge};
use mfd::sim::{MirroredDisplay, ScreenState, SimFaults, SimParams, SimulatedCamera};

use super::MeasureArgs;

/// The measurement on monitor `--display N` (an index of `mfd display --list`).
#[cfg(feature = "display")]
pub(super) fn on_monitor(args: &MeasureArgs, input: super::StationInput) -> anyhow::Result<()> {
    use mfd::acquire::display::window::{run_fullscreen, WindowConfig, WindowDisplay};
    let station = &input.station;
    let monitor: usize = args.display.parse().with_context(|| {
        format!(
            "--display {}: expected `offscreen` or a monitor index from `mfd display --list`",
            args.display
        )
    })?;
    anyhow::ensure!(
        args.settle_ms.is_finite() && (0.0..=10_000.0).contains(&args.settle_ms),
        "--settle-ms: expected 0 to 10000 ms, found {}",
        args.settle_ms
    );
    let config = WindowConfig {
        monitor,
        shading: Shading::new(args.gamma, Dither::Bayer8)?,
        settle: Duration::from_secs_f64(args.settle_ms * 1e-3),
        expect_resolution: Some((station.screen.width, station.screen.height)),
    };
    /// The window handle, borrowed for the measurement.
    struct Borrowed<'a>(&'a mut WindowDisplay);
    impl PatternDisplay for Borrowed<'_> {
        fn resolution(&self) -> (u32, u32) {
            self.0.resolution()
        }
        fn show(
            &mut self,
            index: usize,
            pattern: &mfd::acquire::patterns::Pattern,
        ) -> Result<mfd::acquire::display::Shown, DisplayError> {
            self.0.show(index, pattern)
        }
    }
    let args = args.clone();
    run_fullscreen(config, move |window: &mut WindowDisplay| {
        super::run_with(&args, &input, Box::new(Borrowed(window))).map_err(|e| format!("{e:#}"))
    })?
    .map_err(anyhow::Error::msg)
}

/// The display `--display` names when it is not a monitor: `offscreen` is
/// the wgpu renderer of the fringe shader (lavapipe where there is no GPU);
/// a monitor without feature `display` is an error naming the feature
/// (with it, [`run`] opens the window instead).
///
/// [`run`]: super::run
pub(super) fn open_display(
    name: &str,
    station: &Station,
    settle_ms: f64,
    gamma: f64,
) -> anyhow::Result<Box<dyn PatternDisplay>> {
    anyhow::ensure!(
        settle_ms.is_finite() && (0.0..=10_000.0).contains(&settle_ms),
        "--settle-ms: expected 0 to 10000 ms, found {settle_ms}"
    );
    let settle = Duration::from_secs_f64(settle_ms * 1e-3);
    match name {
        "offscreen" => {
            let shading = Shading::new(gamma, Dither::Bayer8)?;
            let (w, h) = (station.screen.width, station.screen.height);
            Ok(Box::new(OffscreenDisplay::new(w, h, shading, settle)?))
        }
        monitor => Err(DisplayError::NotBuilt {
            backend: monitor.into(),
            feature: "display",
        }
        .into()),
    }
}

/// The devices of a measurement, opened.
pub(super) struct Opened<'a> {
    /// The camera `--camera` names.
    pub(super) camera: Box<dyn Camera>,
    /// The display, mirrored to a simulated camera.
    pub(super) display: Box<dyn PatternDisplay + 'a>,
    /// The camera's configuration from the flags.
    pub(super) camera_config: CameraConfig,
}

/// The camera `--camera` names, opened, and its configuration; a
/// simulated camera sees what `display` shows (the display returned
/// mirrors it to the camera).
pub(super) fn open_camera<'a>(
    args: &MeasureArgs,
    station: &Station,
    display: Box<dyn PatternDisplay + 'a>,
) -> anyhow::Result<Opened<'a>> {
    let mut display = display;
    let spec: CameraSpec = args.camera.parse()?;
    let screen = ScreenState::new();
    let sim = if spec.is_simulated() {
        Some(simulated_camera(args, station, screen.clone())?)
    } else {
        None
    };
    let camera = mfd::live::camera::open(&spec, sim)?;
    if spec.is_simulated() {
        display = Box::new(MirroredDisplay::new(display, screen));
    }
    let simulated = camera.describe().backend == "sim" || args.camera == "aravis:fake";
    let camera_config = CameraConfig {
        exposure_us: args.exposure_us,
        gain_db: args.gain_db,
        pixel_format: simulated
            .then(|| PixelFormat::from_bit_depth(args.bit_depth))
            .flatten(),
        frame_rate_hz: args.frame_rate,
        ..CameraConfig::default()
    };
    Ok(Opened {
        camera,
        display,
        camera_config,
    })
}

/// The simulated camera of `--sim-surfaces`, `--noise`, `--bit-depth` and
/// the `--sim-*` faults, watching `screen`.
fn simulated_camera(
    args: &MeasureArgs,
    station: &Station,
    screen: ScreenState,
) -> anyhow::Result<SimulatedCamera> {
    let (front, back) = super::super::load_surfaces(args.sim_surfaces.as_deref(), station)?;
    // The plate as made: the station's, or wedged otherwise
    // (--sim-wedge-arcmin): the back tilted by the difference.
    let mut truth = station.clone();
    let back = match args.sim_wedge_arcmin {
        Some(arcmin) => {
            let made = Wedge {
                arcmin,
                azimuth_deg: args.sim_wedge_azimuth_deg,
            };
            let ([a, b], [c, d]) = (made.slope(), station.element.wedge.slope());
            truth.element.wedge = made;
            Wedge::from_slope([a - c, b - d]).added_to(&back)?
        }
        None => back,
    };
    let station = &truth;
    let params = SimParams {
        bit_depth: args.bit_depth,
        noise_frac: args.noise,
        // Each run of --repeat sees noise of its own.
        seed: SimParams::default().seed.wrapping_add(args.run_index),
        ..SimParams::default()
    };
    let f = &args.faults;
    anyhow::ensure!(
        f.sim_latency_ms.is_finite() && f.sim_latency_ms >= 0.0,
        "--sim-latency-ms: expected ≥ 0"
    );
    anyhow::ensure!(
        (0.0..1.0).contains(&f.sim_drop_probability),
        "--sim-drop-probability: expected a probability in [0, 1)"
    );
    let faults = SimFaults {
        latency: Duration::from_secs_f64(f.sim_latency_ms * 1e-3),
        drop_every: f.sim_drop_every.filter(|&k| k > 0),
        drop_probability: f.sim_drop_probability,
        seed: f.sim_seed,
        early_every: f.sim_early_every.filter(|&k| k > 0),
        disconnect_after: f.sim_disconnect_after,
    };
    let camera = SimulatedCamera::of_plate(station, front, back, params, screen, faults)?;
    Ok(camera)
}
