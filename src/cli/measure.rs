//! `mfd measure`: live acquisition of a whole schedule, recorded as it
//! arrives and reconstructed at the end with the same stages as
//! `mfd reconstruct`.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use mfd::acquire::camera::{CameraConfig, CameraSpec, PixelFormat};
use mfd::acquire::display::{DisplayError, Dither, OffscreenDisplay, PatternDisplay, Shading};
use mfd::live::{sha256_hex, Counters, Measurement, Prepared, Report, SequencerConfig, Start};
use mfd::optics::station::{Dof, Station};
use mfd::optics::trace::DEFAULT_EDGE_MARGIN_MM;
use mfd::pipeline::{self, find_station_uncertainty, Input, Options};
use mfd::sim::{MirroredDisplay, ScreenState, SimFaults, SimParams, SimulatedCamera};

/// Arguments of `mfd measure`.
#[derive(Args, Clone)]
pub struct MeasureArgs {
    /// Station geometry (mfd-station/1 or /2).
    #[arg(long)]
    station: PathBuf,
    /// The station's uncertainty (mfd-station-uncertainty/1); default:
    /// station_uncertainty.toml beside --station when there is one (as
    /// `mfd calibrate solve` writes it). Its `station` field must name
    /// --station. The result's σ then include the station's geometry;
    /// without one the geometry counts as exact, and the result says so.
    #[arg(long)]
    uncertainty: Option<PathBuf>,
    /// Degrees of freedom estimated jointly with the surfaces (spec names,
    /// comma-separated), as `mfd reconstruct --refine`.
    #[arg(long, value_delimiter = ',', value_parser = super::reconstruct::parse_dof)]
    refine: Vec<Dof>,
    /// Camera: `sim`, `aravis` (first found), `aravis:ID`, `aravis:fake`
    /// (the simulated station behind a GigE Vision fake camera on loopback),
    /// `v4l:/dev/videoN`.
    #[arg(long, default_value = "sim")]
    camera: String,
    /// Display: a monitor name, or `offscreen`.
    #[arg(long, default_value = "offscreen")]
    display: String,
    /// Output folder: acquisition/ (mfd-acquisition/1) and result/.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    schedule: super::ScheduleArgs,
    /// Show exactly the patterns of this schedule file (mfd-schedule/1, as
    /// `mfd plan` writes), in its order, instead of the schedule flags.
    #[arg(long = "schedule", value_name = "TOML", conflicts_with_all = ["directions", "tau_start", "tau_stop", "tau_step", "phases"])]
    schedule_file: Option<PathBuf>,
    /// Simulated cameras: the element's true surfaces (mfd-surfaces/1 or /2); flat when omitted.
    #[arg(long)]
    sim_surfaces: Option<PathBuf>,
    /// Simulated cameras: read noise, standard deviation as a fraction of full scale.
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.0)]
    noise: f64,
    /// Simulated cameras: bits per sample (8, 12 or 16).
    #[arg(long, value_parser = super::check::sim_bit_depth, default_value_t = 16)]
    bit_depth: u32,
    /// Time the display needs after presenting a pattern before it is
    /// settled, ms (LCD response; real monitors take their profile's value).
    #[arg(long, value_parser = super::check::range(0.0, 10_000.0, "ms a display takes to settle"), default_value_t = 2.0)]
    settle_ms: f64,
    /// Display gamma for the offscreen renderer's levels (level =
    /// 255·g^(1/γ); the display profiles in hw/ carry it).
    #[arg(long, value_parser = super::check::gamma, default_value_t = 2.2)]
    gamma: f64,
    /// Exposure time, µs (real cameras; the device's value when omitted).
    #[arg(long, value_parser = super::check::positive)]
    exposure_us: Option<f64>,
    /// Gain, dB (real cameras).
    #[arg(long, value_parser = super::check::finite)]
    gain_db: Option<f64>,
    /// Frame rate of a free-running camera, frames/s.
    #[arg(long, value_parser = super::check::positive)]
    frame_rate: Option<f64>,
    /// Longest wait for a frame after the settle point, ms.
    #[arg(long, value_parser = super::check::positive_int::<u64>, default_value_t = 2000)]
    frame_timeout_ms: u64,
    /// Re-shoots allowed per pattern before giving up.
    #[arg(long, default_value_t = 5)]
    max_reshoots: u32,
    /// Frames each consumer's ring buffer holds.
    #[arg(long, value_parser = super::check::positive_int::<usize>, default_value_t = 16)]
    ring: usize,
    #[command(flatten)]
    faults: FaultArgs,
    /// Continue an interrupted acquisition in --out/acquisition.
    #[arg(long, conflicts_with = "overwrite")]
    resume: bool,
    /// Replace an existing acquisition in --out.
    #[arg(long)]
    overwrite: bool,
    /// Record only; skip the reconstruction.
    #[arg(long)]
    no_reconstruct: bool,
    #[command(flatten)]
    spectral: super::SpectralArgs,
    #[command(flatten)]
    surfaces: super::surfaces_stage::SurfaceArgs,
    #[command(flatten)]
    checks: super::CheckArgs,
    /// Serve the operator's console (live preview, progress, stop, results)
    /// on PORT (127.0.0.1) or HOST:PORT; any but a loopback address needs
    /// the token printed at start. It stays open after the run until Ctrl-C.
    #[arg(long, value_name = "ADDR", value_parser = super::serve::parse_addr)]
    serve: Option<std::net::SocketAddr>,
    /// With --serve: close the console at most this long after the run, s.
    #[arg(long, value_parser = super::check::non_negative, value_name = "SECONDS", requires = "serve")]
    serve_keep_s: Option<f64>,
}

/// Faults the simulated camera injects (for testing the live loop).
#[derive(Args, Clone)]
struct FaultArgs {
    /// Lose every k-th exposure.
    #[arg(long, value_parser = super::check::positive_int::<u64>, value_name = "K")]
    sim_drop_every: Option<u64>,
    /// Lose each exposure with this probability.
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.0)]
    sim_drop_probability: f64,
    /// Expose every k-th triggered frame just before the screen settled.
    #[arg(long, value_parser = super::check::positive_int::<u64>, value_name = "K")]
    sim_early_every: Option<u64>,
    /// Disconnect after this many frames.
    #[arg(long, value_name = "N")]
    sim_disconnect_after: Option<u64>,
    /// Delay from exposure to delivery, ms.
    #[arg(long, value_parser = super::check::range(0.0, 60_000.0, "ms from exposure to delivery"), default_value_t = 0.0)]
    sim_latency_ms: f64,
    /// Seed of the random drops.
    #[arg(long, default_value_t = 1)]
    sim_seed: u64,
}

/// Runs `mfd measure`: on a monitor (feature `display`) inside the
/// fullscreen window's event loop, which must own the main thread, with the
/// measurement on the window's worker thread; else on the offscreen display.
pub fn run(args: &MeasureArgs) -> anyhow::Result<()> {
    #[cfg(feature = "display")]
    if args.display != "offscreen" {
        return on_monitor(args);
    }
    let station = Station::load(&args.station)?;
    let display = open_display(&args.display, &station, args.settle_ms, args.gamma)?;
    run_with(args, display)
}

/// The measurement on monitor `--display N` (an index of `mfd display --list`).
#[cfg(feature = "display")]
fn on_monitor(args: &MeasureArgs) -> anyhow::Result<()> {
    use mfd::acquire::display::window::{run_fullscreen, WindowConfig, WindowDisplay};
    let station = Station::load(&args.station)?;
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
        run_with(&args, Box::new(Borrowed(window))).map_err(|e| format!("{e:#}"))
    })?
    .map_err(anyhow::Error::msg)
}

fn run_with(args: &MeasureArgs, display: Box<dyn PatternDisplay + '_>) -> anyhow::Result<()> {
    let mut display = display;
    let station = Station::load(&args.station)?;
    // Bounded before expansion: frame count (validate) and τ against what
    // the station's screen can show (its Nyquist limit).
    let (sw, sh) = (station.screen.width, station.screen.height);
    let input = |e: anyhow::Error| super::exit::classified(super::exit::Class::Input, e);
    let patterns = match &args.schedule_file {
        Some(p) => {
            let file = mfd::acquire::schedule_file::load(p).map_err(|e| input(e.into()))?;
            file.check_against_screen(p, sw, sh)
                .map_err(|e| input(e.into()))?;
            file.patterns()
        }
        None => {
            let schedule = args.schedule.schedule();
            schedule.validate().map_err(|e| input(e.into()))?;
            schedule
                .check_against_screen(sw, sh)
                .map_err(|e| input(e.into()))?;
            schedule.patterns()
        }
    };
    let spec: CameraSpec = args.camera.parse()?;
    let screen = ScreenState::new();
    let sim = if spec.is_simulated() {
        Some(simulated_camera(args, &station, screen.clone())?)
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
    let start = if args.resume {
        Start::Resume
    } else {
        Start::New {
            overwrite: args.overwrite,
        }
    };
    let solver = (!args.no_reconstruct).then(|| args.spectral.config());
    let sequencer = SequencerConfig {
        frame_timeout: Duration::from_millis(args.frame_timeout_ms),
        max_reshoots: args.max_reshoots,
        capacity: args.ring,
    };
    let dir = args.out.join("acquisition");
    let station_bytes = std::fs::read(&args.station)
        .with_context(|| format!("reading {}", args.station.display()))?;
    let prepared = Prepared {
        station: &station,
        station_sha256: &sha256_hex(&station_bytes),
        patterns,
        camera_config,
        dir: &dir,
        start,
    };
    let mut measurement =
        Measurement::prepare_checked(prepared, camera, display, solver, sequencer)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C handler")?;
    let served = match args.serve {
        Some(addr) => Some(serve_measurement(
            addr,
            args,
            &station,
            &stop,
            &mut measurement,
        )?),
        None => None,
    };
    let t0 = Instant::now();
    let report = run_session(&mut measurement, &stop);
    if let Some(s) = &served {
        s.acquired(&report);
    }
    let report = report?;
    summarise(&report, &measurement);
    let outcome = finish(
        args,
        &station,
        &report,
        &mut measurement,
        t0.elapsed().as_secs_f64(),
        served.as_ref(),
    );
    if let Some(s) = served {
        s.finished(&outcome);
        s.linger(
            args.serve_keep_s
                .map(|k| Duration::from_secs_f64(k.max(0.0))),
        );
    }
    outcome
}

/// `--serve`: the console, tapping the measurement.
fn serve_measurement(
    addr: std::net::SocketAddr,
    args: &MeasureArgs,
    station: &Station,
    stop: &Arc<AtomicBool>,
    measurement: &mut Measurement<'_>,
) -> anyhow::Result<super::serve::Served> {
    use mfd::console::{Mode, Spectral};
    let screen = [station.screen.width, station.screen.height];
    let served =
        super::serve::Served::start(addr, Mode::Measure, stop, screen, &args.out.join("result"))?;
    if !args.no_reconstruct {
        served.console.set_spectral(Spectral::Streaming {
            frames_in: measurement.recorded(),
            frames_total: measurement.patterns().len(),
        });
    }
    measurement.set_tap(Arc::new(served.console.clone()));
    Ok(served)
}

/// The display `--display` names when it is not a monitor: `offscreen` is
/// the wgpu renderer of the fringe shader (lavapipe where there is no GPU);
/// a monitor without feature `display` is an error naming the feature
/// (with it, [`run`] opens the window instead).
fn open_display(
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

fn simulated_camera(
    args: &MeasureArgs,
    station: &Station,
    screen: ScreenState,
) -> anyhow::Result<SimulatedCamera> {
    let (front, back) = super::load_surfaces(args.sim_surfaces.as_deref(), station)?;
    let params = SimParams {
        bit_depth: args.bit_depth,
        noise_frac: args.noise,
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

fn run_session(measurement: &mut Measurement<'_>, stop: &AtomicBool) -> anyhow::Result<Report> {
    let total = measurement.patterns().len() as u64;
    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template(
            "[{bar:30}] {pos}/{len} frames, {msg}, {elapsed} elapsed, eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_position(measurement.recorded() as u64);
    let mut progress = |c: &Counters| {
        bar.set_position((c.first + c.captured) as u64);
        bar.set_message(format!(
            "{:.1} frames/s, {} dropped, {} re-shot, {} waits on consumers",
            c.frames_per_s(),
            c.timeouts + c.incomplete,
            c.reshoots,
            c.backpressure_waits
        ));
    };
    let report = measurement.run(stop, &mut progress);
    bar.finish_and_clear();
    Ok(report?)
}

fn summarise(report: &Report, measurement: &Measurement<'_>) {
    let camera = measurement.camera();
    let c = &report.counters;
    println!(
        "{} {} frames in {:.1} s ({:.1} frames/s); {} of {} recorded in {}",
        if report.interrupted {
            "stopped after"
        } else {
            "captured"
        },
        c.captured,
        c.elapsed_s,
        c.frames_per_s(),
        measurement.recorded(),
        c.total,
        measurement.dir().display()
    );
    println!(
        "  re-shoots {} (timeouts {}, mismatched frames {}, incomplete {}); \
         lost frames {}; stale frames skipped {}; waits on consumers {} ({:.2} s)",
        c.reshoots,
        c.timeouts,
        c.mismatches,
        c.incomplete,
        c.lost_frames,
        c.stale,
        c.backpressure_waits,
        c.backpressure_s
    );
    if let (Some((lo, hi)), Some(mean)) = (c.margin_s, c.mean_margin_s()) {
        println!(
            "  exposures started {:.2} to {:.2} ms (mean {:.2} ms) after the settle point",
            lo * 1e3,
            hi * 1e3,
            mean * 1e3
        );
    }
    if let Some(s) = camera.stream_statistics() {
        println!(
            "  stream: {} buffers completed, {} failed, {} underruns, \
             {} packets resent, {} missing",
            s.completed, s.failures, s.underruns, s.resent_packets, s.missing_packets
        );
    }
}

fn finish(
    args: &MeasureArgs,
    station: &Station,
    report: &Report,
    measurement: &mut Measurement<'_>,
    acquire_s: f64,
    served: Option<&super::serve::Served>,
) -> anyhow::Result<()> {
    if report.interrupted {
        println!(
            "interrupted: continue with `mfd measure ... --resume`, or reconstruct \
             what is there with `mfd reconstruct {}`",
            args.out.join("acquisition").display()
        );
        return Err(super::exit::classified(
            super::exit::Class::Interrupted,
            anyhow::anyhow!(
                "interrupted by the operator: {} of {} frames recorded in {}",
                measurement.recorded(),
                report.counters.total,
                measurement.dir().display()
            ),
        ));
    }
    let Some(solver) = measurement.solver_mut() else {
        return Ok(());
    };
    let opts = args.surfaces.options(DEFAULT_EDGE_MARGIN_MM)?;
    let surfaces = (!args.surfaces.no_surfaces).then_some(opts);
    let station_uncertainty = match surfaces {
        Some(_) => {
            let found =
                find_station_uncertainty(&args.station, station, args.uncertainty.as_deref())?;
            super::output::print_uncertainty_source(found.as_ref(), &args.station);
            found.map(|f| f.uncertainty)
        }
        None => None,
    };
    let (estimator, max_expected_nm) = args.surfaces.estimator()?;
    let options = Options {
        surfaces,
        station_uncertainty,
        refine: args.refine.clone(),
        estimator,
        max_expected_nm,
        limits: args.checks.limits(),
        ..Options::default()
    };
    let mut fitting = |done: usize, total: usize| {
        if let Some(s) = served {
            s.fitting(done, total);
        }
    };
    let mut rec = pipeline::reconstruct(Input::Streamed(solver), station, &options, &mut fitting)?;
    if let Some(s) = rec.spectral.as_mut() {
        s.read_s = acquire_s;
        if let Some(served) = served {
            served.console.set_spectral(mfd::console::Spectral::Done {
                both_found: s.maps.found_both(),
                pixels: s.fitted_pixels,
            });
        }
    }
    let result = args.out.join("result");
    let mut inputs = mfd::pipeline::Inputs::new();
    let manifest = args
        .out
        .join("acquisition")
        .join(mfd::acquire::acquisition::MANIFEST);
    inputs.acquisition =
        mfd::pipeline::InputFile::of(&manifest)
            .ok()
            .map(|m| mfd::pipeline::InputFile {
                path: args.out.join("acquisition").display().to_string(),
                sha256: m.sha256,
            });
    inputs.station = mfd::pipeline::InputFile::of(&args.station).ok();
    rec.inputs = Some(inputs);
    super::output::write_and_print(&rec, &result, &args.checks)?;
    // The acquisition holds a copy of the station: the calibration is
    // where --station came from.
    let options = mfd::report::page::ReportOptions {
        calibration: args.station.parent().map(std::path::Path::to_path_buf),
        ..Default::default()
    };
    let report = mfd::report::page::write(&result, None, &options)?;
    println!("wrote the report {}", report.display());
    Ok(())
}
