//! `mfd bench`: benchmarks that print machine-readable figures.

use std::path::PathBuf;
use std::time::Instant;

use clap::{Args, Subcommand};

use mfd::patterns::Schedule;
use mfd::sim::{RandomSurfaceSpec, SimCamera, SimParams};
use mfd::station::Station;
use mfd::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::zernike::{ZernikeBasis, ZernikeSurface};

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
}

#[derive(Args)]
struct RenderArgs {
    /// Station to render; the default fills the 1296×966 sensor with the
    /// element (80 mm lens), so every pixel carries both reflections.
    #[arg(long, default_value = "calib/bench-fill.toml")]
    station: PathBuf,
    /// Frames to render per measurement.
    #[arg(long, default_value_t = 100)]
    frames: usize,
}

/// Runs `mfd bench`.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    match &args.kind {
        BenchKind::Render(a) => render(a),
    }
}

fn render(args: &RenderArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let e = &station.element;
    let spec = RandomSurfaceSpec::default();
    let basis = ZernikeBasis::new(spec.n_terms, e.aperture_radius_mm, [0.0, 0.0])?;
    let front = ZernikeSurface::new(basis.clone(), spec.draw(1))?;
    let back = ZernikeSurface::new(basis, spec.draw(2))?;
    let plate = Plate::new(&station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let t0 = Instant::now();
    let view = TracedView::trace(&station, &plate);
    let trace_s = t0.elapsed().as_secs_f64();
    let patterns = Schedule::default().patterns();
    let n = args.frames.clamp(1, patterns.len());
    let mut frame = vec![0u16; station.camera.pixel_count()];
    let mut time = |params: SimParams| -> anyhow::Result<f64> {
        let mut cam = SimCamera::new(&view, &station.screen, params)?;
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
    println!(
        "{{\"bench\":\"render\",\"station\":{:?},\"pixels\":{},\"lit_pixels\":{},\"both_paths\":{},\
         \"frames\":{},\"trace_s\":{:.3},\"ms_per_frame\":{:.3},\"ms_per_frame_noisy\":{:.3},\
         \"threads_render\":1}}",
        args.station.display().to_string(),
        station.camera.pixel_count(),
        lit,
        view.count(1),
        n,
        trace_s,
        exact,
        noisy
    );
    Ok(())
}
