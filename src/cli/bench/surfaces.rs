//! `mfd bench surfaces`: the surface solvers on the full-resolution
//! station, from traced screen points with noise at the spectral solver's
//! level; one JSON line of timings and errors.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// Arguments of `mfd bench surfaces`.
#[derive(Args)]
pub struct SurfaceBenchArgs {
    /// Station (default: the paper's, full resolution).
    #[arg(long, default_value = "calib/paper-sim.toml")]
    station: PathBuf,
    /// Zernike terms of the truth and of the fit.
    #[arg(long, value_parser = crate::cli::check::terms, default_value_t = 150)]
    terms: usize,
    /// σ of S1 per coordinate, screen px. The default is what the spectral
    /// solver achieved on this station (2000 frames, 12 bit, 5 % noise):
    /// RMS error 0.110 px for S1 (docs/figures.md); 0 for noise-free.
    #[arg(long, value_parser = crate::cli::check::positive, default_value_t = 0.110)]
    sigma1_px: f64,
    /// σ of S2 per coordinate, screen px (measured there: 0.121 px).
    #[arg(long, value_parser = crate::cli::check::positive, default_value_t = 0.121)]
    sigma2_px: f64,
    /// Seed of the truth surfaces and of the noise.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Skip the joint refinement (front from slopes, back with the front fixed).
    #[arg(long)]
    no_joint: bool,
}

/// Runs the benchmark.
pub fn run(args: &SurfaceBenchArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let e = &station.element;
    let spec = RandomSurfaceSpec {
        n_terms: args.terms,
        ..RandomSurfaceSpec::default()
    };
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let (front, back) = spec.draw_pair(e.aperture_radius_mm, centre, args.seed)?;
    let t = Instant::now();
    let plate = Plate::new(
        &station,
        front.clone(),
        back.clone(),
        DEFAULT_EDGE_MARGIN_MM,
    );
    let view = TracedView::trace(&station, &plate);
    let trace_s = t.elapsed().as_secs_f64();
    let sigma = [args.sigma1_px, args.sigma2_px];
    let (coords, std) = with_noise(view.screen_coords(), sigma, args.seed);
    let noisy = args.sigma1_px > 0.0 || args.sigma2_px > 0.0;
    let unc = if noisy {
        Uncertainty::Std(&std)
    } else {
        Uncertainty::Unknown
    };
    let obs = Observations::from_maps(&station, &coords, unc)?;
    let opts = SurfaceOptions {
        terms: Some(args.terms),
        joint: !args.no_joint,
        ..SurfaceOptions::default()
    };
    let t = Instant::now();
    let sol = reconstruct(&obs, &station, &opts)?;
    let total_s = t.elapsed().as_secs_f64();
    let stage = |name: &str| sol.stages.iter().find(|s| s.name == name);
    let secs = |name: &str| stage(name).map_or(0.0, |s| s.seconds);
    let iters = |name: &str| {
        stage(name).map_or(0, |s| {
            s.lm.as_ref().map_or_else(
                || s.front.as_ref().map_or(0, |f| f.iterations),
                |l| l.iterations,
            )
        })
    };
    let (ff, fb) = (figures(&sol, false), figures(&sol, true));
    use super::{print_json, round};
    print_json(&serde_json::json!({
        "bench": "surfaces",
        "station": args.station.display().to_string(),
        "terms": args.terms,
        "pixels_s1": obs.count(0),
        "pixels_s2": obs.count(1),
        "sigma_px": [args.sigma1_px, args.sigma2_px],
        "trace_s": round(trace_s, 3),
        "front_s": round(secs("front slopes"), 3),
        "front_iterations": iters("front slopes"),
        "back_s": round(secs("back"), 3),
        "back_iterations": iters("back"),
        "joint_s": round(secs("joint"), 3),
        "joint_iterations": iters("joint"),
        "total_s": round(total_s, 3),
        "front_rms_err_nm": rms_difference_nm(sol.front.coefficients_nm(), front.coefficients_nm()),
        "back_rms_err_nm": rms_difference_nm(sol.back.coefficients_nm(), back.coefficients_nm()),
        "front_bound_nm": round(ff.error_rms_nm, 4),
        "back_bound_nm": round(fb.error_rms_nm, 4),
        "reduced_chi2": round(sol.reduced_chi2, 4),
        "condition_number": sol.condition_number,
        "threads": rayon::current_num_threads(),
    }));
    Ok(())
}

/// The traced points with Gaussian noise of σ1 on S1's and σ2 on S2's
/// coordinates (seeded), and those σ per coordinate.
pub(super) fn with_noise(
    mut coords: Vec<f64>,
    sigma_px: [f64; 2],
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed.wrapping_add(1000));
    let mut std = vec![0.0; coords.len()];
    for (k, (c, s)) in coords.iter_mut().zip(std.iter_mut()).enumerate() {
        let sigma = sigma_px[(k / 2) % 2];
        let z: f64 = StandardNormal.sample(&mut rng);
        *c += sigma * z;
        *s = sigma;
    }
    (coords, std)
}
