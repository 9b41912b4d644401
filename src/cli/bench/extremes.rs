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
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// Arguments of `mfd bench extremes`.
#[derive(Args)]
pub struct ExtremesArgs {
    /// σ of the screen points in the noisy runs, px per coordinate.
    #[arg(long, value_parser = crate::cli::check::positive, default_value_t = 0.1)]
    sigma_px: f64,
    /// Seed of the surfaces and the noise.
    #[arg(long, default_value_t = 3)]
    seed: u64,
    /// Print a markdown table instead of one JSON line per case.
    #[arg(long)]
    markdown: bool,
    /// Only these cases (by name, comma-separated); default: all.
    #[arg(long, value_delimiter = ',')]
    case: Vec<String>,
}

/// One case's figures.
struct Outcome {
    points: [usize; 2],
    noise_free_nm: [f64; 2],
    iterations: Vec<usize>,
    /// Error ÷ reported bound and the bounds (nm), front and back, with noise.
    noisy: Result<([f64; 2], [f64; 2]), String>,
    seconds: f64,
    converged: bool,
    condition_number: f64,
}

impl Outcome {
    fn markdown(&self) -> String {
        let noisy = match &self.noisy {
            Ok((r, b)) => format!(
                "{:.2} / {:.2} (bounds {:.2} / {:.2} nm)",
                r[0], r[1], b[0], b[1]
            ),
            Err(e) => format!("stopped: {e}"),
        };
        let iters: Vec<String> = self.iterations.iter().map(|i| i.to_string()).collect();
        format!(
            "| {} / {} | {:.1e} / {:.1e}, {} | {noisy} | {:.2} | {}, κ = {:.1e} |",
            self.points[0],
            self.points[1],
            self.noise_free_nm[0],
            self.noise_free_nm[1],
            iters.join("+"),
            self.seconds,
            if self.converged {
                "converged"
            } else {
                "not converged"
            },
            self.condition_number
        )
    }

    fn json(&self) -> serde_json::Value {
        let (ratio, bound, stopped) = match &self.noisy {
            Ok((r, b)) => (Some(r), Some(b), None),
            Err(e) => (None, None, Some(e.as_str())),
        };
        serde_json::json!({
            "pixels_s1": self.points[0],
            "pixels_s2": self.points[1],
            "noise_free_front_rms_err_nm": self.noise_free_nm[0],
            "noise_free_back_rms_err_nm": self.noise_free_nm[1],
            "iterations": self.iterations,
            "noisy_error_over_bound": ratio,
            "noisy_bound_nm": bound,
            "noisy_stopped": stopped,
            "seconds": super::round(self.seconds, 3),
            "converged": self.converged,
            "condition_number": self.condition_number,
        })
    }
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

/// Runs `mfd bench extremes`: one JSON line per case, or a markdown table.
pub fn run(args: &ExtremesArgs) -> anyhow::Result<()> {
    if args.markdown {
        println!(
            "| case | t (mm) | n | tilt (°) | terms | back RMS (nm) | S1 / S2 px | noise-free: front / back error (nm), iterations | \
             σ = {} px: front / back error ÷ bound | time (s) | outcome |",
            args.sigma_px
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
    }
    if let Some(unknown) = args
        .case
        .iter()
        .find(|n| !CASES.iter().any(|c| c.name == *n))
    {
        let names: Vec<&str> = CASES.iter().map(|c| c.name).collect();
        anyhow::bail!("--case {unknown:?}: expected one of {names:?}");
    }
    let chosen = CASES
        .iter()
        .filter(|c| args.case.is_empty() || args.case.iter().any(|n| n == c.name));
    for c in chosen {
        let station = mfd::optics::station::bench_station(c.thickness_mm, c.index, c.tilt_deg)?;
        let outcome = one(&station, c, args);
        if args.markdown {
            let row = match &outcome {
                Ok(o) => o.markdown(),
                Err(e) => format!("| – | – | – | – | stopped: {} |", crate::error_chain(e)),
            };
            println!(
                "| {} | {} | {} | {} | {} | {} {row}",
                c.name, c.thickness_mm, c.index, c.tilt_deg, c.terms, c.back_rms_nm
            );
            continue;
        }
        let mut figures = serde_json::json!({
            "bench": "extremes",
            "case": c.name,
            "thickness_mm": c.thickness_mm,
            "index": c.index,
            "tilt_deg": c.tilt_deg,
            "terms": c.terms,
            "back_rms_nm": c.back_rms_nm,
            "sigma_px": args.sigma_px,
        });
        match &outcome {
            Ok(o) => {
                if let (Some(f), serde_json::Value::Object(more)) =
                    (figures.as_object_mut(), o.json())
                {
                    f.extend(more);
                }
            }
            Err(e) => figures["stopped"] = crate::error_chain(e).into(),
        }
        super::print_json(&figures);
    }
    Ok(())
}

fn one(station: &Station, c: &Case, args: &ExtremesArgs) -> anyhow::Result<Outcome> {
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
    let iterations: Vec<usize> = sol
        .stages
        .iter()
        .map(|s| {
            s.lm.as_ref().map_or_else(
                || s.front.as_ref().map_or(0, |f| f.iterations),
                |l| l.iterations,
            )
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
    let noisy = match reconstruct(&obs_n, station, &opts) {
        Ok(s) => {
            let bound = [
                figures(&s, false).error_rms_nm,
                figures(&s, true).error_rms_nm,
            ];
            let nf = rms_difference_nm(s.front.coefficients_nm(), front.coefficients_nm());
            let nb = rms_difference_nm(s.back.coefficients_nm(), back.coefficients_nm());
            Ok(([nf / bound[0], nb / bound[1]], bound))
        }
        Err(e) => Err(e.to_string()),
    };
    let converged = sol
        .stages
        .iter()
        .filter_map(|s| s.lm.as_ref())
        .all(|l| l.converged);
    Ok(Outcome {
        points: [n1, n2],
        noise_free_nm: [ef, eb],
        iterations,
        noisy,
        seconds: t.elapsed().as_secs_f64(),
        converged,
        condition_number: sol.condition_number,
    })
}
