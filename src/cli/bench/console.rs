//! `mfd bench console`: the sequencer's waits and pace with no console
//! against a console serving a deliberately slow client
//! (`mfd::console::probe`): the same simulated measurement (recorder on
//! disk, simulated camera and screen) run twice, figures as one JSON line.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clap::Args;

use mfd::acquire::camera::{CameraConfig, PixelFormat};
use mfd::acquire::patterns::Schedule;
use mfd::console::probe::{ProbeReport, SlowClient, Slowness};
use mfd::console::{self, Console, Mode};
use mfd::live::{Measurement, Report, SequencerConfig, Start};
use mfd::optics::station::Station;
use mfd::sim::{MirroredDisplay, ScreenState, SimDisplay, SimFaults, SimParams, SimulatedCamera};

use super::{print_json, random_surfaces, round};

/// Arguments of `mfd bench console`.
#[derive(Args)]
pub struct ConsoleBenchArgs {
    /// Station; the default fills the 1296×966 sensor (large previews).
    #[arg(long, default_value = "calib/bench-fill.toml")]
    station: PathBuf,
    /// Largest τ of the schedule (τ = 1, 2, …; 2 directions × 3 phases each).
    #[arg(long, value_parser = crate::cli::check::positive_int::<u32>, default_value_t = 10)]
    tau_stop: u32,
    /// Screen settle time after each pattern, ms.
    #[arg(long, value_parser = crate::cli::check::range(0.0, 10_000.0, "ms a display takes to settle"), default_value_t = 5.0)]
    settle_ms: f64,
    /// The slow client's time to "draw" a preview before asking for the next, ms.
    #[arg(long, default_value_t = 500)]
    draw_ms: u64,
    /// Bytes it reads at a time from a preview response.
    #[arg(long, value_parser = crate::cli::check::positive_int::<usize>, default_value_t = 4096)]
    chunk_bytes: usize,
    /// Its pause after each chunk, ms.
    #[arg(long, default_value_t = 2)]
    chunk_pause_ms: u64,
    /// WebSocket clients that never read.
    #[arg(long, default_value_t = 4)]
    stalled_sockets: usize,
}

/// Runs the benchmark.
pub fn run(args: &ConsoleBenchArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let without = measure(&station, args, false)?;
    let with = measure(&station, args, true)?;
    let figures = |r: &Report| {
        let c = &r.counters;
        let (lo, hi) = c.margin_s.unwrap_or((f64::NAN, f64::NAN));
        serde_json::json!({
            "frames": c.captured,
            "elapsed_s": round(c.elapsed_s, 3),
            "frames_per_s": round(c.frames_per_s(), 2),
            "waits": c.backpressure_waits,
            "wait_s": round(c.backpressure_s, 4),
            "reshoots": c.reshoots,
            "timeouts": c.timeouts,
            "margin_mean_ms": round(c.mean_margin_s().unwrap_or(f64::NAN) * 1e3, 3),
            "margin_min_ms": round(lo * 1e3, 3),
            "margin_max_ms": round(hi * 1e3, 3),
        })
    };
    let probe = with.1.unwrap_or_default();
    print_json(&serde_json::json!({
        "bench": "console",
        "station": args.station.display().to_string(),
        "pixels": station.camera.pixel_count(),
        "settle_ms": args.settle_ms,
        "without_console": figures(&without.0),
        "with_slow_client": figures(&with.0),
        "slow_client": {
            "draw_ms": args.draw_ms,
            "chunk_bytes": args.chunk_bytes,
            "chunk_pause_ms": args.chunk_pause_ms,
            "previews_received": probe.previews,
            "preview_bytes": probe.preview_bytes,
            "failed_requests": probe.failed_requests,
            "stalled_sockets": probe.stalled_sockets_open,
        },
        "waits_equal": without.0.counters.backpressure_waits == with.0.counters.backpressure_waits,
        "reshoots_equal": without.0.counters.reshoots == with.0.counters.reshoots,
    }));
    Ok(())
}

/// One measurement into a temporary folder, with or without the console
/// and its slow client.
fn measure(
    station: &Station,
    args: &ConsoleBenchArgs,
    console_on: bool,
) -> anyhow::Result<(Report, Option<ProbeReport>)> {
    let tmp = std::env::temp_dir().join(format!(
        "mfd-bench-console-{}-{}",
        std::process::id(),
        console_on
    ));
    let patterns = Schedule {
        tau_start: 1.0,
        tau_stop: f64::from(args.tau_stop.max(1)),
        tau_step: 1.0,
        ..Schedule::default()
    }
    .patterns();
    let (front, back) = random_surfaces(station)?;
    let params = SimParams {
        bit_depth: 12,
        noise_frac: 0.01,
        ..SimParams::default()
    };
    let screen = ScreenState::new();
    let camera = SimulatedCamera::of_plate(
        station,
        front,
        back,
        params,
        screen.clone(),
        SimFaults::default(),
    )?;
    let res = (station.screen.width, station.screen.height);
    let settle = Duration::from_secs_f64(args.settle_ms.max(0.0) * 1e-3);
    let display = MirroredDisplay::new(Box::new(SimDisplay::new(res, settle)), screen);
    let config = CameraConfig {
        pixel_format: PixelFormat::from_bit_depth(12),
        ..CameraConfig::default()
    };
    let mut m = Measurement::prepare(
        station,
        patterns,
        Box::new(camera),
        Box::new(display),
        config,
        &tmp,
        Start::New { overwrite: true },
        None,
        SequencerConfig::default(),
    )?;
    let stop = Arc::new(AtomicBool::new(false));
    let mut served = None;
    if console_on {
        let console = Console::live(Mode::Measure, Arc::clone(&stop), Some([res.0, res.1]));
        let handle = console::serve(SocketAddr::from(([127, 0, 0, 1], 0)), console.clone())?;
        m.set_tap(Arc::new(console));
        let how = Slowness {
            draw_delay: Duration::from_millis(args.draw_ms),
            chunk_bytes: args.chunk_bytes,
            chunk_pause: Duration::from_millis(args.chunk_pause_ms),
            stalled_sockets: args.stalled_sockets,
        };
        let client = SlowClient::start(handle.local_addr(), handle.token(), how)?;
        served = Some((handle, client));
    }
    let report = m.run(&stop, &mut |_| {})?;
    let probe = served.map(|(handle, client)| {
        let p = client.finish();
        handle.shutdown();
        p
    });
    drop(m);
    if let Err(e) = std::fs::remove_dir_all(&tmp) {
        log::warn!("removing {}: {e}", tmp.display());
    }
    Ok((report, probe))
}
