//! `mfd bench`: benchmarks that print machine-readable figures.

mod budget;
mod console;
mod extremes;
mod surfaces;
mod thickness;
mod thin;

use std::path::PathBuf;
use std::time::Instant;

use clap::{Args, Subcommand};

use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};

/// Arguments of `mfd bench`.
#[derive(Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    kind: BenchKind,
}

#[derive(Subcommand)]
enum BenchKind {
    /// Trace a full sensor once, then render frames on one core; prints one
    /// JSON line: trace_s, ms_per_frame (noise-free), ms_per_frame_noisy
    /// (5 % read noise and shot noise), pixels, lit_pixels, frames.
    Render(RenderArgs),
    /// Stream simulated frames of the paper's schedule (or `--schedule`) through a bounded
    /// channel into the spectral solver, without disk; prints one JSON line:
    /// frames_per_s (ingestion), latency_after_last_frame_s (the solve),
    /// peak_rss_bytes, pixels (fitted), frames, the solve's µs per pixel, the
    /// solver's time per frame while frames stream in (ingest_ms_per_frame,
    /// beside the renderer) and alone (ingest_ms_per_frame_quiet), and what
    /// the whole sensor would take and hold at those rates
    /// (full_sensor_ingest_ms_per_frame from the quiet figure,
    /// full_sensor_latency_s, full_sensor_series_bytes).
    Spectral(SpectralBenchArgs),
    /// Spectral error against the Cramér–Rao bound over plate thickness and
    /// refractive index (simulated 48×48 station, paper schedule): a markdown table.
    Thickness(thickness::TableArgs),
    /// Surface solvers on the full-resolution station from traced screen
    /// points with noise at the spectral solver's level; prints one JSON
    /// line: front_s, back_s, back_iterations, joint_s, front_rms_err_nm,
    /// back_rms_err_nm, the bounds, and more.
    Surfaces(surfaces::SurfaceBenchArgs),
    /// Surface solvers at the extremes (thickness 1–40 mm, n 1.4–2.4,
    /// incidence 5–35°, 15–231 terms, a back 10 µm out of flat) on the 48×48
    /// station: a markdown table of errors, iterations and outcomes.
    Extremes(extremes::ExtremesArgs),
    /// The error budget on the full-resolution station: traced screen
    /// points with noise at the spectral solver's level, the surfaces
    /// solved, then `budget()` over all 28 degrees of freedom; prints one
    /// JSON line: solve_s, budget_s (separately), pixels, terms, the
    /// station-induced RMS of each surface.
    Budget(budget::BudgetBenchArgs),
    /// Both surface estimators (per-pixel, surface-domain) over plate
    /// thickness and index from rendered frames (48×48 station, paper
    /// schedule), against the surfaces' Cramér–Rao bound and against what
    /// each reports: one JSON line per plate, or a markdown table.
    Thin(thin::ThinArgs),
    /// A simulated measurement (recorder on disk) without the console and
    /// with a console serving a slow client (previews read slowly, stalled
    /// WebSockets); prints one JSON line: each run's frames/s, waits on
    /// consumers, re-shoots and exposure margins, and what the client got.
    Console(console::ConsoleBenchArgs),
}

#[derive(Args)]
struct SpectralBenchArgs {
    /// Station; the default fills the 1296×966 sensor with the element.
    #[arg(long, default_value = "calib/bench-fill.toml")]
    station: PathBuf,
    /// Stream the patterns of this schedule file (mfd-schedule/1, as `mfd
    /// plan` writes) in its order, instead of the paper's schedule.
    #[arg(long, value_name = "TOML")]
    schedule: Option<PathBuf>,
    /// Fit only a centred square of about this many pixels (the solver
    /// holds 2 bytes per fitted pixel and frame); 0 for every pixel.
    #[arg(long, default_value_t = 20_000)]
    pixels: usize,
    /// Read noise as a fraction of full scale.
    #[arg(long, value_parser = crate::cli::check::non_negative, default_value_t = 0.05)]
    noise: f64,
    /// How the solver keeps the pixels' data: auto, series or statistics.
    #[arg(long, value_enum, default_value_t = mfd::solve::spectral::Engine::Statistics, hide_possible_values = true)]
    engine: mfd::solve::spectral::Engine,
    /// Search every pixel's fits from its spectrum, instead of starting
    /// each from its row neighbour's where that one found both points (the
    /// same answers within 0.03σ, 3–4× slower; for scenes with many
    /// discontinuities).
    #[arg(long)]
    search_every_pixel: bool,
    /// Also time the surfaces after the spectral stage: the per-pixel
    /// route and the surface-domain fit started from it (direct_s,
    /// direct_iterations, full_sensor_direct_s at the measured rate per pixel).
    #[arg(long)]
    direct: bool,
}

#[derive(Args)]
struct RenderArgs {
    /// Station to render; the default fills the 1296×966 sensor with the
    /// element (80 mm lens), so every pixel carries both reflections.
    #[arg(long, default_value = "calib/bench-fill.toml")]
    station: PathBuf,
    /// Frames to render per measurement.
    #[arg(long, value_parser = crate::cli::check::positive_int::<usize>, default_value_t = 100)]
    frames: usize,
}

/// Runs `mfd bench`.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    match &args.kind {
        BenchKind::Render(a) => render(a),
        BenchKind::Spectral(a) => spectral(a),
        BenchKind::Thickness(a) => thickness::run(a),
        BenchKind::Surfaces(a) => surfaces::run(a),
        BenchKind::Extremes(a) => extremes::run(a),
        BenchKind::Budget(a) => budget::run(a),
        BenchKind::Thin(a) => thin::run(a),
        BenchKind::Console(a) => console::run(a),
    }
}

/// Peak resident memory of this process (Linux `VmHWM`), bytes.
fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn spectral(args: &SpectralBenchArgs) -> anyhow::Result<()> {
    use mfd::acquire::acquisition::FrameInfo;
    use mfd::solve::spectral::{SpectralConfig, SpectralSolver};
    let station = Station::load(&args.station)?;
    // The schedule is read before the sensor is traced: a bad file fails at once.
    let patterns = match &args.schedule {
        Some(p) => {
            let file = mfd::acquire::schedule_file::load(p)?;
            file.check_against_screen(p, station.screen.width, station.screen.height)?;
            file.patterns()
        }
        None => Schedule::default().patterns(),
    };
    let (front, back) = random_surfaces(&station)?;
    let plate = Plate::new(&station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let view = TracedView::trace(&station, &plate);
    let frames: Vec<FrameInfo> = FrameInfo::from_patterns(&patterns);
    let (w, h) = (station.camera.width, station.camera.height);
    let roi = (args.pixels > 0).then(|| {
        let side = (args.pixels as f64).sqrt().ceil() as u32;
        let (x0, y0) = ((w.saturating_sub(side)) / 2, (h.saturating_sub(side)) / 2);
        [x0, y0, (x0 + side).min(w), (y0 + side).min(h)]
    });
    let config = SpectralConfig {
        roi,
        engine: args.engine,
        warm_starts: !args.search_every_pixel,
        ..SpectralConfig::default()
    };
    let params = SimParams {
        noise_frac: args.noise,
        bit_depth: 12,
        ..SimParams::default()
    };
    let mut cam = Renderer::new(&view, &station.screen, params)?;
    // The simulated camera keeps what it needs; the traced view of the
    // simulated plate (~100 bytes a pixel) is no part of the instrument's
    // memory and is not held beside the solver.
    drop(view);
    let n_pix = station.camera.pixel_count();
    let quiet_ms = quiet_ingest_ms(&station, &frames, &config, &mut cam, &patterns[0])?;
    let mut solver = SpectralSolver::new(&station, &frames, config)?;
    let (ingest_s, busy_s, last_arrival) = stream(cam, patterns, &mut solver)?;
    let maps = solver.solve()?;
    let solve_s = last_arrival.elapsed().as_secs_f64();
    let fitted = solver.candidate_pixels();
    // What the whole sensor would take at the measured rate per pixel (the
    // solve is per pixel and the cores stay busy) and hold (2 bytes per
    // pixel and frame): the goal is ≤ 10 s and ≤ 4 GiB.
    let scale = n_pix as f64 / fitted.max(1) as f64;
    let nodes = solver.statistics_nodes();
    let surfaces = if args.direct {
        direct_timing(&solver, &maps, &station, scale)?
    } else {
        serde_json::Value::Null
    };
    print_json(&serde_json::json!({
        "bench": "spectral",
        "surfaces": surfaces,
        "station": args.station.display().to_string(),
        "pixels": fitted,
        "sensor_pixels": n_pix,
        "frames": frames.len(),
        "frames_per_s": round(frames.len() as f64 / ingest_s, 1),
        "latency_after_last_frame_s": round(solve_s, 2),
        "solve_us_per_pixel": round(solve_s * 1e6 / fitted.max(1) as f64, 0),
        "both_found": maps.found_both(),
        "series_bytes": solver.series_bytes(),
        "ingest_ms_per_frame": round(busy_s * 1e3 / frames.len() as f64, 3),
        "ingest_ms_per_frame_quiet": round(quiet_ms, 3),
        "full_sensor_ingest_ms_per_frame": round(quiet_ms * scale, 1),
        "full_sensor_latency_s": round(solve_s * scale, 0),
        "full_sensor_series_bytes": (solver.series_bytes() as f64 * scale).round() as u64,
        "peak_rss_bytes": peak_rss_bytes().unwrap_or(0),
        "threads": rayon::current_num_threads(),
        "engine": if nodes.is_some() { "statistics" } else { "series" },
        "nodes": nodes.unwrap_or_default(),
        "warm_starts": !args.search_every_pixel,
    }));
    Ok(())
}

/// The per-pixel surfaces and the surface-domain fit from them, timed.
fn direct_timing(
    solver: &mfd::solve::spectral::SpectralSolver,
    maps: &mfd::solve::spectral::SpectralMaps,
    station: &Station,
    scale: f64,
) -> anyhow::Result<serde_json::Value> {
    use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};
    let station = station.element_frame();
    // A centred patch of the aperture carries few low-order terms: 15.
    let opts = SurfaceOptions {
        terms: Some(15),
        ..SurfaceOptions::default()
    };
    let t = std::time::Instant::now();
    let cov = maps.screen_cov();
    let obs = Observations::from_maps(&station, &maps.screen_coords(), Uncertainty::Cov(&cov))?;
    let per_pixel = reconstruct(&obs, &station, &opts);
    let per_pixel_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let d = mfd::solve::direct::solve(
        solver,
        maps,
        &station,
        per_pixel.as_ref().ok(),
        &opts,
        &mfd::solve::direct::DirectOptions::default(),
    )?;
    let direct_s = t.elapsed().as_secs_f64();
    let surface_s: f64 = d.solution.stages.iter().map(|s| s.seconds).sum();
    Ok(serde_json::json!({
        "per_pixel_surfaces_s": round(per_pixel_s, 2),
        "direct_s": round(direct_s, 2),
        "direct_iterations": d.iterations.len(),
        "direct_converged": d.converged,
        "terms": [d.solution.front.coefficients_nm().len(), d.solution.back.coefficients_nm().len()],
        "last_surface_solve_s": round(surface_s, 2),
        "full_sensor_direct_s": round(direct_s * scale, 0),
    }))
}

/// The solver's ingest alone, ms per frame, with no frames rendered beside
/// it and before the run (so that its memory is not counted twice): a solver
/// takes 32 frames untimed (its memory is touched for the first time), then
/// 192 timed, on both cores.
fn quiet_ingest_ms(
    station: &Station,
    frames: &[mfd::acquire::acquisition::FrameInfo],
    config: &mfd::solve::spectral::SpectralConfig,
    cam: &mut Renderer,
    pattern: &mfd::acquire::patterns::Pattern,
) -> anyhow::Result<f64> {
    let mut probe = mfd::solve::spectral::SpectralSolver::new(station, frames, config.clone())?;
    let mut frame = vec![0u16; station.camera.pixel_count()];
    cam.render(pattern, 0, &mut frame);
    // 32 untimed and up to 192 timed, all before the schedule's last frame
    // (whose push seals the statistics).
    let end = frames.len().saturating_sub(1).min(224);
    let warm = end.min(32);
    for k in 0..warm {
        probe.push_frame(k, &frame)?;
    }
    let t = Instant::now();
    for k in warm..end {
        probe.push_frame(k, &frame)?;
    }
    Ok(t.elapsed().as_secs_f64() * 1e3 / (end - warm).max(1) as f64)
}

/// Streams the schedule into `solver` as a camera would: a thread renders
/// frames into a bounded ring buffer of 8. Returns the seconds from the
/// first frame to the last, the seconds spent inside the solver (what it
/// leaves of the camera's frame period), and the last frame's arrival, from
/// which the latency runs (its push ingests the last block and seals the
/// statistics).
fn stream(
    mut cam: Renderer,
    patterns: Vec<mfd::acquire::patterns::Pattern>,
    solver: &mut mfd::solve::spectral::SpectralSolver,
) -> anyhow::Result<(f64, f64, Instant)> {
    let (w, h) = cam.resolution();
    let n_pix = w * h;
    let (tx, rx) = crossbeam_channel::bounded::<(usize, Vec<u16>)>(8);
    let producer = std::thread::spawn(move || {
        for (k, p) in patterns.iter().enumerate() {
            let mut frame = vec![0u16; n_pix];
            cam.render(p, k as u64, &mut frame);
            if tx.send((k, frame)).is_err() {
                break;
            }
        }
    });
    let t0 = Instant::now();
    let mut busy_s = 0.0;
    let mut last_arrival = Instant::now();
    for (k, frame) in rx.iter() {
        let t = Instant::now();
        last_arrival = t;
        solver.push_frame(k, &frame)?;
        busy_s += t.elapsed().as_secs_f64();
    }
    let ingest_s = t0.elapsed().as_secs_f64();
    producer
        .join()
        .map_err(|_| anyhow::anyhow!("the frame producer panicked"))?;
    Ok((ingest_s, busy_s, last_arrival))
}

fn random_surfaces(station: &Station) -> anyhow::Result<(ZernikeSurface, ZernikeSurface)> {
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    Ok(RandomSurfaceSpec::default().draw_pair(e.aperture_radius_mm, centre, 1)?)
}

fn render(args: &RenderArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let (front, back) = random_surfaces(&station)?;
    let plate = Plate::new(&station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let t0 = Instant::now();
    let view = TracedView::trace(&station, &plate);
    let trace_s = t0.elapsed().as_secs_f64();
    let patterns = Schedule::default().patterns();
    let n = args.frames.clamp(1, patterns.len());
    let mut frame = vec![0u16; station.camera.pixel_count()];
    let mut time = |params: SimParams| -> anyhow::Result<f64> {
        let mut cam = Renderer::new(&view, &station.screen, params)?;
        cam.render(&patterns[0], 0, &mut frame); // warm the direction cache
        let t = Instant::now();
        for (k, p) in patterns.iter().take(n).enumerate() {
            cam.render(p, k as u64, &mut frame);
        }
        Ok(t.elapsed().as_secs_f64() * 1e3 / n as f64)
    };
    let exact = time(SimParams::default())?;
    let noisy = time(SimParams {
        noise_frac: 0.05,
        full_well_electrons: Some(20_000.0),
        ..SimParams::default()
    })?;
    let lit = view
        .pixels
        .iter()
        .filter(|p| p.front.is_ok() || p.back.is_ok())
        .count();
    print_json(&serde_json::json!({
        "bench": "render",
        "station": args.station.display().to_string(),
        "pixels": station.camera.pixel_count(),
        "lit_pixels": lit,
        "both_paths": view.count(1),
        "frames": n,
        "trace_s": round(trace_s, 3),
        "ms_per_frame": round(exact, 3),
        "ms_per_frame_noisy": round(noisy, 3),
        "threads_render": 1,
    }));
    Ok(())
}

/// One benchmark's figures as one JSON line on stdout (what `scripts/bench.sh`
/// collects and a user's `jq` reads).
pub fn print_json(figures: &serde_json::Value) {
    println!("{figures}");
}

/// `x` rounded to `digits` decimals: the figures' precision, not the
/// float's (NaN stays NaN and is written as `null`).
pub fn round(x: f64, digits: i32) -> f64 {
    let scale = 10f64.powi(digits);
    (x * scale).round() / scale
}
