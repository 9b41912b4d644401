//! `mfd bench budget`: the error budget's linearisation on the
//! full-resolution station, timed apart from the solve it linearises.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use nalgebra::DMatrix;

use mfd::budget::assemble::budget;
use mfd::optics::station::{Dof, Station, StationUncertainty};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// Arguments of `mfd bench budget`.
#[derive(Args)]
pub struct BudgetBenchArgs {
    /// Station (default: the paper's, full resolution).
    #[arg(long, default_value = "calib/paper-sim.toml")]
    station: PathBuf,
    /// Zernike terms of the truth and of the fit.
    #[arg(long, value_parser = crate::cli::check::terms, default_value_t = 150)]
    terms: usize,
    /// σ of S1 and S2 per coordinate, screen px (as `bench surfaces`).
    #[arg(long, value_parser = crate::cli::check::positive, num_args = 2, default_values_t = [0.110, 0.121])]
    sigma_px: Vec<f64>,
    /// Seed of the truth surfaces and of the noise.
    #[arg(long, default_value_t = 7)]
    seed: u64,
}

/// A 1σ of the paper's order for every degree of freedom, in its unit.
fn paper_order_std(d: Dof) -> f64 {
    use Dof::*;
    match d {
        CameraX | CameraY | CameraZ | ScreenX | ScreenY | ScreenZ => 0.1,
        CameraRx | CameraRy | CameraRz | ScreenRx | ScreenRy | ScreenRz => 0.01,
        FocalLength => 0.01,
        Cx | Cy => 0.5,
        K1 | K2 | K3 => 1e-3,
        P1 | P2 => 1e-5,
        ScreenPitch => 1e-5,
        ElementX | ElementY | ElementZ => 0.01,
        ElementRx | ElementRy => 0.01,
        Thickness => 0.002,
        RefractiveIndex => 1e-4,
    }
}

/// Runs the benchmark.
pub fn run(args: &BudgetBenchArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let e = &station.element;
    let spec = RandomSurfaceSpec {
        n_terms: args.terms,
        ..RandomSurfaceSpec::default()
    };
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let (front, back) = spec.draw_pair(e.aperture_radius_mm, centre, args.seed)?;
    let plate = Plate::new(&station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let view = TracedView::trace(&station, &plate);
    let sigma = [args.sigma_px[0], args.sigma_px[1]];
    let (coords, std) = super::surfaces::with_noise(view.screen_coords(), sigma, args.seed);
    let obs = Observations::from_maps(&station, &coords, Uncertainty::Std(&std))?;
    let opts = SurfaceOptions {
        terms: Some(args.terms),
        ..SurfaceOptions::default()
    };
    let t = Instant::now();
    let sol = reconstruct(&obs, &station, &opts)?;
    let solve_s = t.elapsed().as_secs_f64();
    let names = Dof::ALL.to_vec();
    let var: Vec<f64> = names.iter().map(|d| paper_order_std(*d).powi(2)).collect();
    let unc = StationUncertainty {
        station: args.station.display().to_string(),
        covariance: DMatrix::from_diagonal(&nalgebra::DVector::from_vec(var)),
        names,
        correlated: 0,
    };
    let t = Instant::now();
    let b = budget(&obs, &station, &unc, &sol, &opts)?;
    let budget_s = t.elapsed().as_secs_f64();
    let rms = |c: &DMatrix<f64>| (3..c.nrows()).map(|k| c[(k, k)]).sum::<f64>().sqrt();
    use super::{print_json, round};
    print_json(&serde_json::json!({
        "bench": "budget",
        "station": args.station.display().to_string(),
        "terms": args.terms,
        "pixels_s1": obs.count(0),
        "pixels_s2": obs.count(1),
        "dofs": b.dofs.len(),
        "solve_s": round(solve_s, 3),
        "budget_s": round(budget_s, 3),
        "front_total_rms_nm": round(rms(&b.front_total_cov_nm2), 3),
        "back_total_rms_nm": round(rms(&b.back_total_cov_nm2), 3),
        "identifiability_entries": b.identifiability.len(),
        "threads": rayon::current_num_threads(),
    }));
    Ok(())
}
