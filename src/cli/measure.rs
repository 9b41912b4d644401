//! `mfd measure`: live acquisition of a whole schedule, recorded as it
//! arrives and reconstructed at the end with the same stages as
//! `mfd reconstruct`.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;

use mfd::acquire::display::PatternDisplay;
use mfd::live::{sha256_hex, Measurement, Prepared, SequencerConfig, Start};
use mfd::optics::station::{Dof, Station};

mod devices;
mod finish;
mod repeat;
mod session;

#[cfg(feature = "display")]
use devices::on_monitor;
use devices::{open_camera, open_display};
use finish::finish;
use session::{run_session, serve_measurement, summarise};

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
    /// Simulated cameras: the plate's true wedge between its faces, arcmin
    /// (the station's own when omitted): a plate made otherwise than the
    /// station declares.
    #[arg(long, value_parser = super::check::range(0.0, mfd::optics::station::MAX_WEDGE_ARCMIN, "a wedge in arcmin"))]
    sim_wedge_arcmin: Option<f64>,
    /// Simulated cameras: the true wedge's azimuth, degrees from the
    /// element's +x' towards +y'.
    #[arg(long, value_parser = super::check::finite, default_value_t = 0.0, requires = "sim_wedge_arcmin", allow_hyphen_values = true)]
    sim_wedge_azimuth_deg: f64,
    /// Start from the station's wedge without looking in the recorded
    /// frames for the back reflection first (as `mfd reconstruct
    /// --keep-station-wedge`).
    #[arg(long)]
    keep_station_wedge: bool,
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
    /// Measure N times in a row, each into --out/run-K (acquisition and
    /// result), then write --out/repeatability.json: per figure and per
    /// coefficient the spread over the runs against the reported σ.
    #[arg(long, value_name = "N", value_parser = super::check::positive_int::<usize>, default_value_t = 1, conflicts_with_all = ["resume", "no_reconstruct", "serve"])]
    repeat: usize,
    /// Which run of --repeat this is (the simulated camera's noise seed).
    #[arg(skip)]
    run_index: u64,
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
    /// With --serve: a name of this machine the console may be opened by,
    /// as `mfd serve --allow-host`; repeatable.
    #[arg(long, value_name = "NAME", requires = "serve")]
    allow_host: Vec<String>,
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
    if args.repeat > 1 {
        return repeat::run_repeated(args, &StationInput::load(&args.station)?);
    }
    #[cfg(feature = "display")]
    if args.display != "offscreen" {
        return on_monitor(args, StationInput::load(&args.station)?);
    }
    let station = StationInput::load(&args.station)?;
    let display = open_display(&args.display, &station.station, args.settle_ms, args.gamma)?;
    run_with(args, &station, display)
}

/// The station file, read once: the station, and the SHA-256 of the very
/// bytes it was parsed from, for the acquisition's setup and the result's
/// inputs.
#[derive(Clone)]
pub(super) struct StationInput {
    /// The station.
    pub station: Station,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
}

impl StationInput {
    fn load(path: &std::path::Path) -> anyhow::Result<Self> {
        let (station, bytes) = Station::load_with_bytes(path)?;
        Ok(Self {
            station,
            sha256: sha256_hex(&bytes),
        })
    }
}

/// The Ctrl-C flag: one handler per process (a second is refused), shared
/// by every run of `--repeat` (an interrupted run ends them all).
fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    static STOP: std::sync::OnceLock<Arc<AtomicBool>> = std::sync::OnceLock::new();
    if let Some(s) = STOP.get() {
        return Ok(Arc::clone(s));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C handler")?;
    Ok(Arc::clone(STOP.get_or_init(|| stop)))
}

/// The measurement on `display`: the schedule's patterns shown and
/// recorded as they arrive, then the reconstruction; with `--serve`, the
/// console beside it.
fn run_with(
    args: &MeasureArgs,
    input: &StationInput,
    display: Box<dyn PatternDisplay + '_>,
) -> anyhow::Result<()> {
    let station = &input.station;
    let patterns = args
        .schedule
        .patterns(args.schedule_file.as_deref(), station)?;
    let devices::Opened {
        camera,
        display,
        camera_config,
    } = open_camera(args, station, display)?;
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
    let prepared = Prepared {
        station,
        station_sha256: &input.sha256,
        patterns,
        camera_config,
        dir: &dir,
        start,
    };
    let mut measurement =
        Measurement::prepare_checked(prepared, camera, display, solver, sequencer)?;
    let stop = stop_flag()?;
    let served = match args.serve {
        Some(addr) => Some(serve_measurement(
            addr,
            args,
            station,
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
        input,
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
