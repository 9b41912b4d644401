//! `mfd reconstruct`: every reconstruction stage that exists, from an
//! acquisition folder.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use mfd::acquire::acquisition::Acquisition;
use mfd::optics::station::Station;
use mfd::optics::trace::DEFAULT_EDGE_MARGIN_MM;
use mfd::solve::spectral::{flags, SpectralConfig, SpectralMaps, SpectralSolver};
use mfd::solve::surfaces::Uncertainty;

/// Arguments of `mfd reconstruct`.
#[derive(Args)]
pub struct ReconstructArgs {
    /// Acquisition folder (mfd-acquisition/1); or give --screen-coords.
    #[arg(required_unless_present = "screen_coords")]
    acquisition: Option<PathBuf>,
    /// Rerun only the surface stage from these screen points
    /// ([rows, columns, 2, 2] float64, spec layout; e.g. from `mfd trace` or
    /// an earlier reconstruction); needs --station.
    #[arg(long, conflicts_with = "acquisition", requires = "station")]
    screen_coords: Option<PathBuf>,
    /// Their standard deviations, same layout; default: screen_cov.npy
    /// ([rows, columns, 4, 4], covariance of u1, v1, u2, v2) or else
    /// screen_std.npy beside --screen-coords when one exists; without
    /// either the scale is estimated from the residuals.
    #[arg(long, requires = "screen_coords")]
    screen_std: Option<PathBuf>,
    /// Output folder: screen_coords.npy [rows, cols, 2, 2] (u, v of front and
    /// back, screen px, NaN where not found), screen_std.npy (their standard
    /// deviations, px), screen_cov.npy [rows, cols, 4, 4] (covariance of u1,
    /// v1, u2, v2, px²), amplitudes.npy [rows, cols, 4] (A, B1, B2, B3 in
    /// counts), tau_max.npy, residual_rms.npy (counts), separation_bins.npy
    /// (front–back separation in Fourier bins), reflections.npy (u8: model
    /// chosen, 0–3), flags.npy (u16 bits: 1 no data, 2 no fringe signal,
    /// 4 saturated samples excluded, 8 one reflection, 16 three reflections,
    /// 32 reflections not separable, 64 offset disagrees with the geometry,
    /// 128 not converged, 256 negative amplitude, 512 outside the band the
    /// statistics engine keeps).
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
    #[command(flatten)]
    spectral: super::SpectralArgs,
    #[command(flatten)]
    surfaces: super::surfaces_stage::SurfaceArgs,
}

/// Runs `mfd reconstruct`.
pub fn run(args: &ReconstructArgs) -> anyhow::Result<()> {
    if args.roi.as_ref().is_some_and(|r| r.len() != 4) {
        anyhow::bail!("--roi takes four numbers x0,y0,x1,y1");
    }
    let surface_opts = args.surfaces.options(args.edge_margin_mm)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let Some(acq_dir) = &args.acquisition else {
        return from_screen_coords(args, &surface_opts);
    };
    let mut acq = Acquisition::open(acq_dir)?;
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
        ..args.spectral.config()?
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
    let surfaces = (!args.surfaces.no_surfaces).then_some(&surface_opts);
    solve_and_write(
        &mut solver,
        &station,
        &args.out,
        t0.elapsed().as_secs_f64(),
        surfaces,
    )
}

/// The stages after the frames are in: the spectral solve, its maps, and
/// (with `surfaces`) the surface stage, all written into `out`; prints the
/// summaries (`read_s`: seconds spent getting the frames). `mfd measure`
/// calls this with its streamed solver.
pub fn solve_and_write(
    solver: &mut SpectralSolver,
    station: &Station,
    out: &std::path::Path,
    read_s: f64,
    surfaces: Option<&mfd::solve::surfaces::SurfaceOptions>,
) -> anyhow::Result<()> {
    let t1 = Instant::now();
    let maps = solver.solve()?;
    let solve_s = t1.elapsed().as_secs_f64();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    maps.write(out)?;
    summarise(&maps, solver.candidate_pixels(), read_s, solve_s);
    println!("wrote {}", out.join("screen_coords.npy").display());
    if let Some(opts) = surfaces {
        let cov = maps.screen_cov();
        let unc = Uncertainty::Cov(&cov);
        super::surfaces_stage::run(station, &maps.screen_coords(), unc, opts, out)?;
        println!("wrote {}", out.join("surfaces.json").display());
    }
    Ok(())
}

/// The surface stage alone, from a screen_coords.npy.
fn from_screen_coords(
    args: &ReconstructArgs,
    opts: &mfd::solve::surfaces::SurfaceOptions,
) -> anyhow::Result<()> {
    let (Some(coords_path), Some(station_path)) = (&args.screen_coords, &args.station) else {
        anyhow::bail!("give an acquisition folder, or --screen-coords with --station");
    };
    let station = Station::load(station_path)?;
    let cam = &station.camera;
    let load = |path: &std::path::Path, k: usize| -> anyhow::Result<Vec<f64>> {
        let expect = if k == 2 {
            vec![cam.height as usize, cam.width as usize, 2, 2]
        } else {
            vec![cam.height as usize, cam.width as usize, 4, 4]
        };
        let (shape, data) = mfd::formats::npy::read_f64(path)?;
        anyhow::ensure!(
            shape == expect,
            "{}: shape {shape:?}, expected {expect:?} (rows, columns, reflection, u/v) for {}",
            path.display(),
            station_path.display()
        );
        Ok(data)
    };
    let coords = load(coords_path, 2)?;
    let beside = |name: &str| {
        let p = coords_path.with_file_name(name);
        p.exists().then_some(p)
    };
    let (unc_path, is_cov) = match &args.screen_std {
        Some(p) => (Some(p.clone()), false),
        None => match beside("screen_cov.npy") {
            Some(p) => (Some(p), true),
            None => (beside("screen_std.npy"), false),
        },
    };
    let unc_data = match &unc_path {
        Some(p) => {
            println!("uncertainty of the screen points from {}", p.display());
            Some(load(p, if is_cov { 4 } else { 2 })?)
        }
        None => {
            println!("no screen_std.npy: the residuals set the uncertainty scale");
            None
        }
    };
    let unc = match (&unc_data, is_cov) {
        (None, _) => Uncertainty::Unknown,
        (Some(d), true) => Uncertainty::Cov(d),
        (Some(d), false) => Uncertainty::Std(d),
    };
    super::surfaces_stage::run(&station, &coords, unc, opts, &args.out)?;
    println!("wrote {}", args.out.join("surfaces.json").display());
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
    let count = |f: &dyn Fn(u16) -> bool| {
        maps.pixels
            .iter()
            .filter(|p| p.flags & flags::NO_DATA == 0 && f(p.flags))
            .count()
    };
    let left = count(&|f| f & flags::OUT_OF_BAND != 0 && f & flags::NO_SIGNAL == 0);
    if left > 0 {
        println!("  {left} pixels: signal or fit outside the statistics engine's band");
    }
    let quiet = count(&|f| f & flags::OUT_OF_BAND != 0 && f & flags::NO_SIGNAL != 0);
    if quiet + left > fitted / 2 {
        println!(
            "  most pixels show no signal within the band the statistics engine keeps: the \
             element may sit away from where the station file puts it; rerun with \
             --band-bins 8 or --engine series"
        );
    }
    if let Some(s) = maps.saturation_counts {
        println!("  saturation level {s} counts");
    }
}
