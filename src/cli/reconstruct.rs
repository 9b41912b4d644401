//! `mfd reconstruct`: every reconstruction stage that exists, from an
//! acquisition folder.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use mfd::acquisition::Acquisition;
use mfd::spectral::{flags, SpectralConfig, SpectralMaps, SpectralSolver};
use mfd::station::Station;
use mfd::trace::DEFAULT_EDGE_MARGIN_MM;

/// Arguments of `mfd reconstruct`.
#[derive(Args)]
pub struct ReconstructArgs {
    /// Acquisition folder (mfd-acquisition/1).
    acquisition: PathBuf,
    /// Output folder: screen_coords.npy [rows, cols, 2, 2] (u, v of front and
    /// back, screen px, NaN where not found), screen_std.npy (their standard
    /// deviations, px), amplitudes.npy [rows, cols, 4] (A, B1, B2, B3 in
    /// counts), tau_max.npy, residual_rms.npy (counts), separation_bins.npy
    /// (front–back separation in Fourier bins), reflections.npy (u8: model
    /// chosen, 0–3), flags.npy (u16 bits: 1 no data, 2 no fringe signal,
    /// 4 saturated samples excluded, 8 one reflection, 16 three reflections,
    /// 32 reflections not separable, 64 offset disagrees with the geometry,
    /// 128 not converged, 256 negative amplitude).
    #[arg(long)]
    out: PathBuf,
    /// Station file; default: the one the acquisition names.
    #[arg(long)]
    station: Option<PathBuf>,
    /// Allow a third reflection (second internal round trip, paper §5.1b).
    #[arg(long)]
    third_reflection: bool,
    /// Exclude samples at or above this count; default: the full scale
    /// (2^b − 1) when the data reach it.
    #[arg(long)]
    saturation: Option<u16>,
    /// Starting τ_max of the modulation falloff; default: the largest τ.
    #[arg(long)]
    tau_max_guess: Option<f64>,
    /// Fit pixels up to this many camera pixels beyond where the station
    /// predicts the element.
    #[arg(long, default_value_t = 4)]
    margin_px: u32,
    /// Rim of the element beyond the aperture radius, mm.
    #[arg(long, default_value_t = DEFAULT_EDGE_MARGIN_MM)]
    edge_margin_mm: f64,
    /// Only this region of camera pixels: x0,y0,x1,y1 (columns x0..x1, rows y0..y1).
    #[arg(long, value_delimiter = ',')]
    roi: Option<Vec<u32>>,
}

/// Runs `mfd reconstruct`.
pub fn run(args: &ReconstructArgs) -> anyhow::Result<()> {
    if args.roi.as_ref().is_some_and(|r| r.len() != 4) {
        anyhow::bail!("--roi takes four numbers x0,y0,x1,y1");
    }
    let mut acq = Acquisition::open(&args.acquisition)?;
    let station_path = args
        .station
        .clone()
        .unwrap_or_else(|| acq.station_path().to_path_buf());
    let station = Station::load(&station_path)?;
    acq.check_resolution(station.camera.width, station.camera.height)?;
    let config = SpectralConfig {
        tau_max_guess: args.tau_max_guess,
        third_reflection: args.third_reflection,
        saturation_counts: args.saturation,
        margin_px: args.margin_px,
        edge_margin_mm: args.edge_margin_mm,
        roi: args.roi.as_ref().map(|r| [r[0], r[1], r[2], r[3]]),
        ..SpectralConfig::default()
    };
    let t0 = Instant::now();
    let mut solver = SpectralSolver::new(&station, acq.frames(), config)?;
    let bar = ProgressBar::new(acq.frames().len() as u64).with_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("reading");
    let mut frame = Vec::new();
    for f in acq.frames() {
        acq.read_frame(f.index, &mut frame)?;
        solver.push_frame(f.index, &frame)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    solve_and_write(&solver, &args.out, t0.elapsed().as_secs_f64())
}

/// The stages after the frames are in: solves, writes the maps into `out`
/// and prints the summary (`read_s`: seconds spent getting the frames).
/// `mfd measure` calls this with its streamed solver.
pub fn solve_and_write(solver: &SpectralSolver, out: &Path, read_s: f64) -> anyhow::Result<()> {
    let t1 = Instant::now();
    let maps = solver.solve()?;
    let solve_s = t1.elapsed().as_secs_f64();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    maps.write(out)?;
    summarise(&maps, solver.candidate_pixels(), read_s, solve_s);
    println!("wrote {}", out.join("screen_coords.npy").display());
    Ok(())
}

fn summarise(maps: &SpectralMaps, fitted: usize, read_s: f64, solve_s: f64) {
    let both = maps.found_both();
    let median = |k: usize| {
        let mut v: Vec<f64> = maps
            .pixels
            .iter()
            .map(|p| p.std[k][0].hypot(p.std[k][1]))
            .filter(|s| s.is_finite())
            .collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    println!(
        "spectral: {fitted} pixels fitted in {solve_s:.1} s (frames read in {read_s:.1} s); \
         both reflections found in {both}; median σ(S1) {:.4} px, σ(S2) {:.4} px",
        median(0),
        median(1)
    );
    let names = [
        (flags::NO_SIGNAL, "no fringe signal"),
        (flags::SATURATED, "saturated samples excluded"),
        (flags::ONE_REFLECTION, "one reflection"),
        (flags::THREE_REFLECTIONS, "three reflections"),
        (flags::UNRESOLVED, "reflections not separable"),
        (flags::OFFSET_MISMATCH, "offset disagrees with geometry"),
        (flags::NOT_CONVERGED, "not converged"),
        (flags::NEGATIVE_AMPLITUDE, "negative amplitude"),
    ];
    for (bit, name) in names {
        let n = maps
            .pixels
            .iter()
            .filter(|p| p.flags & bit != 0 && p.flags & flags::NO_DATA == 0)
            .count();
        if n > 0 {
            println!("  {n} pixels: {name}");
        }
    }
    if let Some(s) = maps.saturation_counts {
        println!("  saturation level {s} counts");
    }
}
