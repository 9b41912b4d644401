//! `mfd bench extremes`: the surface solvers at the edges of their domain
//! (thickness, index, incidence, term count, a back far from flat), from
//! exact traced screen points, noise-free and with noise; a markdown table.

use std::time::Instant;

use clap::Args;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::report::{figures, rms_difference_nm};
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// Arguments of `mfd bench extremes`.
#[derive(Args)]
pub struct ExtremesArgs {
    /// σ of the screen points in the noisy runs, px per coordinate.
    #[arg(long, default_value_t = 0.1)]
    sigma_px: f64,
    /// Seed of the surfaces and the noise.
    #[arg(long, default_value_t = 3)]
    seed: u64,
}

/// One scenario: plate, geometry, model size, back departure.
struct Case {
    name: &'static str,
    thickness_mm: f64,
    index: f64,
    tilt_deg: f64,
    terms: usize,
    back_rms_nm: f64,
}

const fn case(name: &'static str, t: f64, n: f64, tilt: f64, terms: usize, back: f64) -> Case {
    Case {
        name,
        thickness_mm: t,
        index: n,
        tilt_deg: tilt,
        terms,
        back_rms_nm: back,
    }
}

const CASES: [Case; 14] = [
    case("reference", 10.0, 1.5, 15.0, 36, 60.0),
    case("thin", 1.0, 1.5, 15.0, 36, 60.0),
    case("thick", 40.0, 1.5, 15.0, 36, 60.0),
    case("low index", 10.0, 1.4, 15.0, 36, 60.0),
    case("high index", 10.0, 2.4, 15.0, 36, 60.0),
    case("near normal", 10.0, 1.5, 5.0, 36, 60.0),
    case("oblique", 10.0, 1.5, 35.0, 36, 60.0),
    case("few terms", 10.0, 1.5, 15.0, 15, 60.0),
    case("150 terms", 10.0, 1.5, 15.0, 150, 60.0),
    case("231 terms", 10.0, 1.5, 15.0, 231, 60.0),
    case("back 10 µm", 10.0, 1.5, 15.0, 36, 10_000.0),
    case("thick, oblique, n 2.4", 40.0, 2.4, 35.0, 36, 60.0),
    case("thin, near normal, n 1.4", 1.0, 1.4, 5.0, 36, 60.0),
    case(
        "thick, oblique, n 2.4, 231 terms",
        40.0,
        2.4,
        35.0,
        231,
        60.0,
    ),
];

/// Runs `mfd bench extremes`.
pub fn run(args: &ExtremesArgs) -> anyhow::Result<()> {
    println!(
        "| case | t (mm) | n | tilt (°) | terms | back RMS (nm) | S1 / S2 px | noise-free: front / back error (nm), iterations | \
         σ = {} px: front / back error ÷ bound | time (s) | outcome |",
        args.sigma_px
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for c in &CASES {
        let station = mfd::optics::station::bench_station(c.thickness_mm, c.index, c.tilt_deg)?;
        let row = match one(&station, c, args) {
            Ok(r) => r,
            Err(e) => format!("| – | – | – | – | stopped: {} |", crate::error_chain(&e)),
        };
        println!(
            "| {} | {} | {} | {} | {} | {} {row}",
            c.name, c.thickness_mm, c.index, c.tilt_deg, c.terms, c.back_rms_nm
        );
    }
    Ok(())
}

fn one(station: &Station, c: &Case, args: &ExtremesArgs) -> anyhow::Result<String> {
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let spec = RandomSurfaceSpec {
        n_terms: c.terms,
        ..RandomSurfaceSpec::default()
    };
    let front = ZernikeSurface::new(
        mfd::optics::zernike::ZernikeBasis::new(c.terms, e.aperture_radius_mm, centre)?,
        spec.draw(args.seed),
    )?;
    let back_spec = RandomSurfaceSpec {
        rms_nm: c.back_rms_nm,
        ..spec.clone()
    };
    let back = ZernikeSurface::new(front.basis().clone(), back_spec.draw(args.seed + 1))?;
    let view = TracedView::trace(
        station,
        &Plate::new(station, front.clone(), back.clone(), 3.0),
    );
    let coords = view.screen_coords();
    let opts = SurfaceOptions {
        terms: Some(c.terms),
        ..SurfaceOptions::default()
    };
    let t = Instant::now();
    let obs = Observations::from_maps(station, &coords, Uncertainty::Unknown)?;
    let (n1, n2) = (obs.count(0), obs.count(1));
    let sol = reconstruct(&obs, station, &opts)?;
    let iters: Vec<String> = sol
        .stages
        .iter()
        .map(|s| {
            s.lm.as_ref()
                .map_or_else(
                    || s.front.as_ref().map_or(0, |f| f.iterations),
                    |l| l.iterations,
                )
                .to_string()
        })
        .collect();
    let ef = rms_difference_nm(sol.front.coefficients_nm(), front.coefficients_nm());
    let eb = rms_difference_nm(sol.back.coefficients_nm(), back.coefficients_nm());
    // Noisy: the same points with Gaussian noise, σ known.
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(args.seed + 77);
    let noisy: Vec<f64> = coords
        .iter()
        .map(|x| {
            let z: f64 = StandardNormal.sample(&mut rng);
            x + args.sigma_px * z
        })
        .collect();
    let std = vec![args.sigma_px; coords.len()];
    let obs_n = Observations::from_maps(station, &noisy, Uncertainty::Std(&std))?;
    let noisy_part = match reconstruct(&obs_n, station, &opts) {
        Ok(s) => {
            let (bf, bb) = (
                figures(&s, false).error_rms_nm,
                figures(&s, true).error_rms_nm,
            );
            let nf = rms_difference_nm(s.front.coefficients_nm(), front.coefficients_nm());
            let nb = rms_difference_nm(s.back.coefficients_nm(), back.coefficients_nm());
            format!(
                "{:.2} / {:.2} (bounds {bf:.2} / {bb:.2} nm)",
                nf / bf,
                nb / bb
            )
        }
        Err(e) => format!("stopped: {e}"),
    };
    let converged = sol
        .stages
        .iter()
        .filter_map(|s| s.lm.as_ref())
        .all(|l| l.converged);
    Ok(format!(
        "| {n1} / {n2} | {ef:.1e} / {eb:.1e}, {} | {noisy_part} | {:.2} | {}, κ = {:.1e} |",
        iters.join("+"),
        t.elapsed().as_secs_f64(),
        if converged {
            "converged"
        } else {
            "not converged"
        },
        sol.condition_number
    ))
}
