//! `mfd bench thin`: both surface estimators (per-pixel and surface-domain)
//! over plate thickness and index, from rendered frames, against the
//! surfaces' Cramér–Rao bound of the acquisition and against what each
//! reports.

use std::time::Instant;

use clap::Args;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::budget::scene::{scene, Radiometry, SceneOptions};
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{RandomSurfaceSpec, SimParams};
use mfd::solve::direct::{self, DirectOptions};
use mfd::solve::surfaces::report::figures as surface_figures;
use mfd::solve::surfaces::{
    reconstruct, Observations, SurfaceOptions, SurfaceSolution, Uncertainty,
};

use super::{print_json, round};

/// Arguments of `mfd bench thin`.
#[derive(Args)]
pub struct ThinArgs {
    /// Plate thicknesses, mm.
    #[arg(long, value_parser = crate::cli::check::positive, value_delimiter = ',', default_values_t = [1.0, 2.0, 3.0, 5.0, 10.0, 30.0])]
    thickness_mm: Vec<f64>,
    /// Refractive indices.
    #[arg(long, value_parser = crate::cli::check::refractive_index, value_delimiter = ',', default_values_t = [1.46, 1.5, 2.2])]
    index: Vec<f64>,
    /// Read noise, fraction of full scale (0: noise-free).
    #[arg(long, value_parser = crate::cli::check::non_negative, default_value_t = 0.05)]
    noise: f64,
    /// Ambient light, in units of full-white screen radiance (`mfd simulate
    /// --ambient`): the dark level the fringes' troughs reach.
    #[arg(long, value_parser = crate::cli::check::non_negative, default_value_t = 0.01)]
    ambient: f64,
    /// Also render the path with two internal round trips (S3; its Fresnel
    /// weight is R² of the back's: 2 % at n = 2.2, 0.2 % at n = 1.5),
    /// which the estimators do not model.
    #[arg(long)]
    third_reflection: bool,
    /// Terms of the true surfaces (Noll 1…N; 4…N at 60 nm RMS, tilts 100 nm).
    #[arg(long, value_parser = crate::cli::check::positive_int::<usize>, default_value_t = 15)]
    truth_terms: usize,
    /// Terms fitted; default: the estimators choose (BIC).
    #[arg(long, value_parser = crate::cli::check::terms)]
    terms: Option<usize>,
    /// Seeds of the noise (one acquisition each).
    #[arg(long, value_delimiter = ',', default_values_t = [5])]
    seeds: Vec<u64>,
    /// Spectral engine: auto, series or statistics.
    #[arg(long, value_enum, default_value_t = mfd::solve::spectral::Engine::Auto, hide_possible_values = true)]
    engine: mfd::solve::spectral::Engine,
    /// Print a markdown table instead of one JSON line per row.
    #[arg(long)]
    markdown: bool,
    /// Also print, per seed, one JSON line with each fitted coefficient's
    /// error and σ (the surface-domain fit), for looking at a bias term by term.
    #[arg(long)]
    coefficients: bool,
}

/// One estimator's figures on one acquisition.
#[derive(Debug, Clone, Copy, Default)]
struct Figures {
    /// RMS error, piston and tilt removed, nm (front, back).
    error_nm: [f64; 2],
    /// Expected RMS error it reports, nm.
    reported_nm: [f64; 2],
    /// Σ over coefficients j ≥ 2 of (error/σ)², and their count.
    z2: f64,
    zn: usize,
    /// Terms fitted (front).
    terms: usize,
}

/// Runs `mfd bench thin`.
pub fn run(args: &ThinArgs) -> anyhow::Result<()> {
    if args.markdown {
        if args.noise == 0.0 {
            println!("Noise-free: the error columns give the errors in nm (there is no bound).\n");
        }
        println!(
            "| t (mm) | n | S2−S1 (bins) | bound front / back (nm) | per-pixel error/bound | \
             surface-domain error/bound | error/reported | RMS(error/σ) | iterations | s |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|");
    }
    for &n in &args.index {
        for &t in &args.thickness_mm {
            row(args, t, n)?;
        }
    }
    Ok(())
}

fn row(args: &ThinArgs, t: f64, n: f64) -> anyhow::Result<()> {
    let station = super::thickness::small_station(t, n)?;
    let spec = RandomSurfaceSpec {
        n_terms: args.truth_terms,
        ..RandomSurfaceSpec::default()
    };
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let (front, back) = spec.draw_pair(e.aperture_radius_mm, centre, 31)?;
    let truth = [
        front.coefficients_nm().to_vec(),
        back.coefficients_nm().to_vec(),
    ];
    let view = TracedView::trace(
        &station,
        &Plate::new(&station, front.clone(), back.clone(), 3.0),
    );
    let frames = FrameInfo::from_patterns(&Schedule::default().patterns());
    let surface = SurfaceOptions {
        terms: args.terms,
        ..SurfaceOptions::default()
    };
    let (mut pp, mut dd) = (Vec::new(), Vec::new());
    let (mut iterations, mut seconds, mut sep) = (Vec::new(), 0.0, f64::NAN);
    for &seed in &args.seeds {
        let params = SimParams {
            noise_frac: args.noise,
            ambient: args.ambient,
            third_reflection: args.third_reflection,
            seed,
            ..SimParams::default()
        };
        let (solver, maps, _) =
            super::thickness::render_and_solve(&station, &view, &params, args.engine)?;
        sep = direct::median_separation_bins(&solver);
        let cov = maps.screen_cov();
        let obs = Observations::from_maps(&station, &maps.screen_coords(), Uncertainty::Cov(&cov))?;
        let per_pixel = reconstruct(&obs, &station, &surface);
        pp.push(per_pixel.as_ref().ok().map(|s| figures(s, &truth)));
        let t0 = Instant::now();
        let d = direct::solve(
            &solver,
            &maps,
            &station,
            per_pixel.as_ref().ok(),
            &surface,
            &DirectOptions::default(),
        );
        seconds += t0.elapsed().as_secs_f64();
        match d {
            Ok(d) => {
                iterations.push(d.iterations.len());
                if args.coefficients {
                    print_coefficients([t, n], seed, &d.solution, &truth);
                }
                dd.push(Some(figures(&d.solution, &truth)));
            }
            Err(e) => {
                log::warn!("t {t} mm, n {n}, seed {seed}: {e}");
                dd.push(None);
            }
        }
    }
    let terms = dd
        .iter()
        .flatten()
        .map(|f| f.terms)
        .next()
        .unwrap_or(args.truth_terms);
    let bound = surface_bound(&station, (front, back), &frames, args.noise, terms)?;
    print_row(args, [t, n], sep, bound, &pp, &dd, &iterations, seconds);
    Ok(())
}

/// One JSON line: per surface, each coefficient's error (fitted − truth)
/// and σ, nm, Noll order from j = 1.
fn print_coefficients([t, n]: [f64; 2], seed: u64, sol: &SurfaceSolution, truth: &[Vec<f64>; 2]) {
    let one = |fitted: &[f64], std: &[f64], truth: &[f64]| {
        let rows: Vec<[f64; 2]> = fitted
            .iter()
            .zip(std)
            .enumerate()
            .map(|(j, (&c, &s))| {
                let e = c - truth.get(j).copied().unwrap_or(0.0);
                [round(e, 3), round(s, 3)]
            })
            .collect();
        rows
    };
    print_json(&serde_json::json!({
        "bench": "thin-coefficients",
        "thickness_mm": t,
        "index": n,
        "seed": seed,
        "front_error_sigma_nm": one(sol.front.coefficients_nm(), &sol.front_std_nm, &truth[0]),
        "back_error_sigma_nm": one(sol.back.coefficients_nm(), &sol.back_std_nm, &truth[1]),
    }));
}

/// Error, reported error and z-scores of `sol` against `truth`.
fn figures(sol: &SurfaceSolution, truth: &[Vec<f64>; 2]) -> Figures {
    let mut f = Figures {
        terms: sol.front.coefficients_nm().len(),
        ..Figures::default()
    };
    let fitted = [sol.front.coefficients_nm(), sol.back.coefficients_nm()];
    let std = [&sol.front_std_nm, &sol.back_std_nm];
    for k in 0..2 {
        f.error_nm[k] = rms_difference_nm(fitted[k], &truth[k]);
        f.reported_nm[k] = surface_figures(sol, k == 1).error_rms_nm;
        for (j, (&c, &s)) in fitted[k].iter().zip(std[k].iter()).enumerate() {
            if j >= 1 && s > 0.0 {
                let tj = truth[k].get(j).copied().unwrap_or(0.0);
                f.z2 += ((c - tj) / s).powi(2);
                f.zn += 1;
            }
        }
    }
    f
}

/// The surfaces' Cramér–Rao bound of the acquisition, expected RMS error
/// (piston and tilt removed) per surface, nm: every pixel's bound at the
/// truth (all its parameters free), through the surfaces' normal
/// equations with `terms` per surface ([`scene`]).
fn surface_bound(
    station: &Station,
    truth: (ZernikeSurface, ZernikeSurface),
    frames: &[FrameInfo],
    noise: f64,
    terms: usize,
) -> anyhow::Result<[f64; 2]> {
    if noise == 0.0 {
        return Ok([0.0; 2]);
    }
    let opts = SceneOptions {
        radiometry: Radiometry {
            noise_frac: noise,
            ..Radiometry::default()
        },
        terms,
        edge_margin_mm: 3.0,
        bound_stride_px: Some(1),
    };
    let s = scene(station, truth, frames, &opts)?;
    let rms = |back| surface_figures(&s.solution, back).error_rms_nm;
    Ok([rms(false), rms(true)])
}

/// Root mean square over the seeds of each surface's error, and of the
/// reported error; `None` when an estimator failed on any seed.
fn pooled(runs: &[Option<Figures>]) -> Option<([f64; 2], [f64; 2], f64)> {
    let ok: Vec<Figures> = runs.iter().copied().collect::<Option<_>>()?;
    let n = ok.len().max(1) as f64;
    let ms =
        |f: &dyn Fn(&Figures) -> f64| (ok.iter().map(|x| f(x).powi(2)).sum::<f64>() / n).sqrt();
    let err = [ms(&|x| x.error_nm[0]), ms(&|x| x.error_nm[1])];
    let rep = [ms(&|x| x.reported_nm[0]), ms(&|x| x.reported_nm[1])];
    let z = (ok.iter().map(|x| x.z2).sum::<f64>()
        / ok.iter().map(|x| x.zn).sum::<usize>().max(1) as f64)
        .sqrt();
    Some((err, rep, z))
}

#[allow(clippy::too_many_arguments)]
fn print_row(
    args: &ThinArgs,
    [t, n]: [f64; 2],
    sep: f64,
    bound: [f64; 2],
    pp: &[Option<Figures>],
    dd: &[Option<Figures>],
    iterations: &[usize],
    seconds: f64,
) {
    let p = pooled(pp);
    let d = pooled(dd);
    // Noise-free (no bound): the errors themselves, nm.
    let ratio = |e: [f64; 2], b: [f64; 2]| {
        let r = |e: f64, b: f64| if b > 0.0 { e / b } else { e };
        [r(e[0], b[0]), r(e[1], b[1])]
    };
    if args.markdown {
        let cell = |r: Option<[f64; 2]>| match r {
            Some(r) => format!("{:.2} / {:.2}", r[0], r[1]),
            None => "nothing measured".into(),
        };
        let (de, dr, dz) = match d {
            Some((e, r, z)) => (
                cell(Some(ratio(e, bound))),
                cell(Some(ratio(e, r))),
                format!("{z:.2}"),
            ),
            None => ("failed".into(), "—".into(), "—".into()),
        };
        let its: Vec<String> = iterations.iter().map(|i| i.to_string()).collect();
        println!(
            "| {t} | {n} | {sep:.2} | {:.2} / {:.2} | {} | {de} | {dr} | {dz} | {} | {:.1} |",
            bound[0],
            bound[1],
            cell(p.map(|(e, _, _)| ratio(e, bound))),
            its.join(", "),
            seconds / args.seeds.len().max(1) as f64,
        );
        return;
    }
    let fig = |x: Option<([f64; 2], [f64; 2], f64)>| match x {
        Some((e, r, z)) => serde_json::json!({
            "front_error_nm": round(e[0], 3), "back_error_nm": round(e[1], 3),
            "front_reported_nm": round(r[0], 3), "back_reported_nm": round(r[1], 3),
            "rms_error_over_sigma": round(z, 3),
        }),
        None => serde_json::Value::Null,
    };
    print_json(&serde_json::json!({
        "bench": "thin",
        "thickness_mm": t,
        "index": n,
        "noise": args.noise,
        "seeds": args.seeds.len(),
        "median_separation_bins": round(sep, 3),
        "bound_front_nm": round(bound[0], 3),
        "bound_back_nm": round(bound[1], 3),
        "per_pixel": fig(p),
        "surface_domain": fig(d),
        "iterations": iterations,
        "surface_domain_seconds": round(seconds / args.seeds.len().max(1) as f64, 3),
    }));
}
