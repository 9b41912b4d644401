//! `mfd tradeoff`: speed against accuracy, measured. The simulated station
//! over a grid of schedules (frames per direction), Zernike term counts and
//! iteration limits; surface errors against the truth, the solver's own
//! uncertainty, and compute time; a CSV, a markdown table and a plot.
//! With `--designed`, also the schedules `mfd plan` designs for the same
//! frame budgets (predicted bound, achieved error, acquisition time).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::pipeline::{surfaces_from_frames, Estimator};
use mfd::plot::{line_plot_png, Panel, Series};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::{SpectralConfig, SpectralMaps, SpectralSolver};
use mfd::solve::surfaces::lm::LmOptions;
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::SurfaceOptions;

/// Arguments of `mfd tradeoff`.
#[derive(Args)]
pub struct TradeoffArgs {
    /// Station; default: the 48×48 bench station (10 mm, n = 1.5), whose
    /// every pixel samples the Ø 51 mm aperture, so a grid runs in minutes.
    #[arg(long)]
    station: Option<PathBuf>,
    /// Frames per direction (τ from 0.5 in steps of 0.5: τ_stop = 0.5 N).
    #[arg(long, value_parser = super::check::positive_int::<usize>, value_delimiter = ',', default_value = "50,100,200,400")]
    frames: Vec<usize>,
    /// Zernike terms per surface.
    #[arg(long, value_parser = super::check::int_range(1usize, 231, "Noll terms the surfaces support"), value_delimiter = ',', default_value = "15,36,66")]
    terms: Vec<usize>,
    /// Iteration limits (spectral and surface Levenberg–Marquardt alike).
    #[arg(long, value_parser = super::check::positive_int::<usize>, value_delimiter = ',', default_value = "3,30")]
    max_iter: Vec<usize>,
    /// Read noise, fraction of full scale.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = 0.02)]
    noise: f64,
    /// Seed of the surfaces (36 terms, 60 nm RMS) and the noise.
    #[arg(long, default_value_t = 5)]
    seed: u64,
    /// Output folder: tradeoff.csv, tradeoff.md, tradeoff.png.
    #[arg(long)]
    out: PathBuf,
    /// Also a schedule designed by `mfd plan` for each frame budget (the
    /// same frames in total), at the largest term count and iteration
    /// limit; its note gives the predicted bound and the acquisition time.
    #[arg(long)]
    designed: bool,
    /// Noise seeds of each designed row (the surfaces stay those of
    /// --seed): the achieved error is the RMS over them; default: --seed.
    #[arg(long, value_delimiter = ',')]
    seeds: Vec<u64>,
    /// What the rendered falloff acts on, as `mfd simulate --falloff`:
    /// tau (every direction alike) or screen-period (a blur's: a plain
    /// direction's finer fringes fall off sooner).
    #[arg(long, value_enum, default_value_t = mfd::sim::Falloff::Tau)]
    falloff: mfd::sim::Falloff,
}

/// One grid point's outcome.
struct Row {
    frames: usize,
    terms: usize,
    max_iter: usize,
    found: [f64; 2],
    error_nm: [f64; 2],
    reported_nm: [f64; 2],
    spectral_s: f64,
    surfaces_s: f64,
    note: String,
    /// Acquisition time at the planner's default timing, s.
    acquisition_s: f64,
    /// The planner's predicted bound, nm (NaN where not measured).
    predicted_nm: [f64; 2],
    /// A designed schedule (not the uniform family).
    designed: bool,
    /// The planner's verdict: the spectral stage measures this schedule.
    measurable: bool,
}

/// Runs `mfd tradeoff`.
pub fn run(args: &TradeoffArgs) -> anyhow::Result<()> {
    let station = match &args.station {
        Some(p) => Station::load(p)?,
        None => mfd::optics::station::bench_station(10.0, 1.5, 15.0)?,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let (front, back) =
        RandomSurfaceSpec::default().draw_pair(e.aperture_radius_mm, centre, args.seed)?;
    let view = TracedView::trace(
        &station,
        &Plate::new(&station, front.clone(), back.clone(), 3.0),
    );
    let mut rows = Vec::new();
    let mut popts = mfd::plan::PlanOptions::default();
    popts.radiometry.noise_frac = args.noise;
    for &n in &args.frames {
        let frames = FrameInfo::from_patterns(&uniform(n).patterns());
        let acquisition_s = popts.timing.seconds(&frames);
        for &it in &args.max_iter {
            let t = Instant::now();
            let solved = spectral(&station, &view, n, it, args)?;
            let spectral_s = t.elapsed().as_secs_f64();
            for &terms in &args.terms {
                let mut row = surfaces(
                    &station,
                    &solved,
                    (&front, &back),
                    (n, terms, it),
                    spectral_s,
                );
                row.acquisition_s = acquisition_s;
                let p = mfd::plan::predict(
                    &station,
                    &frames,
                    &mfd::plan::PlanOptions {
                        terms,
                        ..popts.clone()
                    },
                )?;
                row.predicted_nm = [
                    p.front.rms_nm,
                    p.back.as_ref().map_or(f64::NAN, |b| b.rms_nm),
                ];
                row.measurable = p.not_measurable_because.is_none();
                if !row.measurable {
                    row.note = format!("PLANNER: not measurable; {}", row.note);
                }
                rows.push(row);
                let r = rows.last().expect("just pushed");
                eprintln!(
                    "frames/dir {n}, terms {terms}, max_iter {it}: front {:.2} nm, back {:.2} nm, {:.1} s {}",
                    r.error_nm[0], r.error_nm[1], r.spectral_s + r.surfaces_s, r.note
                );
            }
        }
    }
    if args.designed {
        designed_rows(&station, &view, (&front, &back), args, &mut rows)?;
    }
    write_outputs(&rows, args)
}

/// One row per frame budget for the schedule `mfd plan` designs.
fn designed_rows(
    station: &Station,
    view: &TracedView,
    truth: (&ZernikeSurface, &ZernikeSurface),
    args: &TradeoffArgs,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let terms = args.terms.iter().copied().max().unwrap_or(36);
    let it = args.max_iter.iter().copied().max().unwrap_or(30);
    let mut opts = mfd::plan::DesignOptions::default();
    opts.plan.radiometry.noise_frac = args.noise;
    opts.plan.terms = terms;
    let seeds = if args.seeds.is_empty() {
        vec![args.seed]
    } else {
        args.seeds.clone()
    };
    for &n in &args.frames {
        let t = Instant::now();
        let d = mfd::plan::design(station, mfd::plan::Budget::Frames(2 * n), &opts)?;
        let design_s = t.elapsed().as_secs_f64();
        let mut per_seed = Vec::new();
        for &seed in &seeds {
            let t = Instant::now();
            let solved = solve_frames(station, view, &d.frames, it, args, seed + n as u64)?;
            let row = surfaces(
                station,
                &solved,
                truth,
                (n, terms, it),
                t.elapsed().as_secs_f64(),
            );
            eprintln!(
                "designed {} frames, noise seed {}: front {:.2} nm, back {:.2} nm {}",
                2 * n,
                seed + n as u64,
                row.error_nm[0],
                row.error_nm[1],
                row.note
            );
            per_seed.push(row);
        }
        let mut row = combine(&per_seed);
        let p = &d.prediction;
        row.acquisition_s = p.seconds;
        row.designed = true;
        row.measurable = p.not_measurable_because.is_none();
        row.predicted_nm = [
            p.front.rms_nm,
            p.back.as_ref().map_or(f64::NAN, |b| b.rms_nm),
        ];
        let ratio = |k: usize| row.error_nm[k] / row.predicted_nm[k];
        let spread = |s: Option<&mfd::plan::SurfacePrediction>| {
            s.map_or(f64::NAN, |s| 100.0 * s.rms_relative_spread(per_seed.len()))
        };
        row.note = format!(
            "designed (plan {design_s:.1} s, start share {:.2} of τ ≤ {:.0}, stage {:.0} % found): predicted {:.2} / {} nm; achieved/predicted ×{:.2} / ×{:.2} (RMS of {} noise seeds, expected seed spread ±{:.0} % / ±{:.0} %: {}){}{}",
            d.uniform_share,
            d.start_tau_max,
            100.0 * p.stage.found_fraction,
            p.front.rms_nm,
            p.back
                .as_ref()
                .map_or("—".into(), |b| format!("{:.2}", b.rms_nm)),
            ratio(0),
            ratio(1),
            per_seed.len(),
            spread(Some(&p.front)),
            spread(p.back.as_ref()),
            per_seed
                .iter()
                .map(|r| format!("{:.2}/{:.2}", r.error_nm[0], r.error_nm[1]))
                .collect::<Vec<_>>()
                .join(", "),
            p.not_measurable_because
                .as_ref()
                .map_or(String::new(), |w| format!("; PLANNER: not measurable ({w})")),
            if row.note.is_empty() {
                String::new()
            } else {
                format!("; {}", row.note)
            }
        );
        eprintln!("designed {} frames: {}", 2 * n, row.note);
        rows.push(row);
    }
    Ok(())
}

/// The rows of one schedule over several noise seeds as one: errors and
/// reported σ as the RMS over the seeds (NaN when any seed measured
/// nothing), points found and times as means, the notes of seeds that
/// had one.
fn combine(rows: &[Row]) -> Row {
    let n = rows.len() as f64;
    let rms = |f: &dyn Fn(&Row) -> f64| (rows.iter().map(|r| f(r).powi(2)).sum::<f64>() / n).sqrt();
    let mean = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).sum::<f64>() / n;
    let mut notes: Vec<&str> = rows
        .iter()
        .map(|r| r.note.as_str())
        .filter(|s| !s.is_empty())
        .collect();
    notes.dedup();
    Row {
        frames: rows[0].frames,
        terms: rows[0].terms,
        max_iter: rows[0].max_iter,
        found: [mean(&|r| r.found[0]), mean(&|r| r.found[1])],
        error_nm: [rms(&|r| r.error_nm[0]), rms(&|r| r.error_nm[1])],
        reported_nm: [rms(&|r| r.reported_nm[0]), rms(&|r| r.reported_nm[1])],
        spectral_s: mean(&|r| r.spectral_s),
        surfaces_s: mean(&|r| r.surfaces_s),
        note: notes.join("; "),
        acquisition_s: f64::NAN,
        predicted_nm: [f64::NAN; 2],
        designed: false,
        measurable: false,
    }
}

/// Renders `frames` on the fly and runs the spectral solver.
fn solve_frames(
    station: &Station,
    view: &TracedView,
    frames: &[FrameInfo],
    it: usize,
    args: &TradeoffArgs,
    seed: u64,
) -> anyhow::Result<Solved> {
    let params = SimParams {
        noise_frac: args.noise,
        seed,
        falloff: args.falloff,
        ..SimParams::default()
    };
    let mut cam = Renderer::new(view, &station.screen, params)?;
    let config = SpectralConfig {
        max_iter: it.max(1),
        ..SpectralConfig::default()
    };
    let mut solver = SpectralSolver::new(station, frames, config)?;
    let mut buf = vec![0u16; station.camera.pixel_count()];
    for (k, f) in frames.iter().enumerate() {
        let p = mfd::acquire::patterns::Pattern {
            direction_deg: f.direction_deg,
            tau: f.tau,
            phase_rad: f.phase_rad,
        };
        cam.render(&p, k as u64, &mut buf);
        solver.push_frame(k, &buf)?;
    }
    checked(solver, station)
}

/// A spectral stage that has run: the solver (its schedule and prior,
/// which the surface-domain fit needs) and its maps.
struct Solved {
    solver: SpectralSolver,
    maps: SpectralMaps,
}

/// The solver's maps with the quality pass `mfd reconstruct` makes
/// (fits far above the noise, points far from the station's prediction:
/// set to NaN), so that the achieved error is the pipeline's.
fn checked(mut solver: SpectralSolver, station: &Station) -> anyhow::Result<Solved> {
    let mut maps = solver.solve()?;
    let c = mfd::pipeline::consistency::check(
        &mut maps,
        solver.prior(),
        station,
        solver.design(),
        mfd::pipeline::Limits::default(),
    );
    log::debug!("tradeoff: {}", c.note);
    Ok(Solved { solver, maps })
}

/// The uniform family: τ from 0.5 in steps of 0.5 to 0.5 n, n frames per direction.
fn uniform(n: usize) -> Schedule {
    Schedule {
        tau_start: 0.5,
        tau_stop: 0.5 * n as f64,
        tau_step: 0.5,
        ..Schedule::default()
    }
}

/// Renders the schedule on the fly (no disk) and runs the spectral solver.
fn spectral(
    station: &Station,
    view: &TracedView,
    n: usize,
    it: usize,
    args: &TradeoffArgs,
) -> anyhow::Result<Solved> {
    let patterns = uniform(n).patterns();
    let params = SimParams {
        noise_frac: args.noise,
        seed: args.seed + n as u64,
        falloff: args.falloff,
        ..SimParams::default()
    };
    let mut cam = Renderer::new(view, &station.screen, params)?;
    let config = SpectralConfig {
        max_iter: it.max(1),
        ..SpectralConfig::default()
    };
    let mut solver = SpectralSolver::new(station, &FrameInfo::from_patterns(&patterns), config)?;
    let mut buf = vec![0u16; station.camera.pixel_count()];
    for (k, p) in patterns.iter().enumerate() {
        cam.render(p, k as u64, &mut buf);
        solver.push_frame(k, &buf)?;
    }
    checked(solver, station)
}

/// The surfaces of a solved stage, by `mfd reconstruct`'s default
/// estimator (`auto`: the surface-domain fit where the reflections are
/// closer than its rule, or where the per-pixel route measures nothing),
/// against the truth.
fn surfaces(
    station: &Station,
    solved: &Solved,
    truth: (&ZernikeSurface, &ZernikeSurface),
    (frames, terms, max_iter): (usize, usize, usize),
    spectral_s: f64,
) -> Row {
    let maps = &solved.maps;
    let total = |k: usize| maps.pixels.iter().filter(|p| p.s[k][0].is_finite()).count() as f64;
    let mut row = Row {
        frames,
        terms,
        max_iter,
        found: [total(0), total(1)],
        error_nm: [f64::NAN; 2],
        reported_nm: [f64::NAN; 2],
        spectral_s,
        surfaces_s: f64::NAN,
        note: String::new(),
        acquisition_s: f64::NAN,
        predicted_nm: [f64::NAN; 2],
        designed: false,
        measurable: false,
    };
    let opts = SurfaceOptions {
        terms: Some(terms),
        lm: LmOptions {
            max_iter: max_iter.max(2),
            ..LmOptions::default()
        },
        ..SurfaceOptions::default()
    };
    let t = Instant::now();
    let result = surfaces_from_frames(&solved.solver, maps, station, &opts, Estimator::Auto);
    row.surfaces_s = t.elapsed().as_secs_f64();
    match result {
        Ok((_, sol, direct)) => {
            if direct.is_some() {
                row.note = "surface-domain fit".into();
            }
            // What `mfd reconstruct` would withhold is not counted as
            // measured (`pipeline::withheld`'s rules): both surfaces where
            // the surface-domain fit did not converge, a surface whose
            // expected error is at least its fitted RMS.
            let unconverged = direct.as_ref().is_some_and(|d| !d.converged);
            let withheld = [false, true].map(|back| {
                let f = figures(&sol, back);
                unconverged || (f.error_rms_nm > 0.0 && f.error_rms_nm >= f.rms_nm)
            });
            row.error_nm = [
                rms_difference_nm(sol.front.coefficients_nm(), truth.0.coefficients_nm()),
                rms_difference_nm(sol.back.coefficients_nm(), truth.1.coefficients_nm()),
            ];
            row.reported_nm = [
                figures(&sol, false).error_rms_nm,
                figures(&sol, true).error_rms_nm,
            ];
            if sol
                .stages
                .iter()
                .filter_map(|s| s.lm.as_ref())
                .any(|l| !l.converged)
            {
                row.note = join_note(&row.note, "iteration limit");
            }
            for (k, name) in ["front", "back"].iter().enumerate() {
                if withheld[k] {
                    row.error_nm[k] = f64::NAN;
                    row.reported_nm[k] = f64::NAN;
                    row.note = join_note(
                        &row.note,
                        &format!("{name} withheld as `mfd reconstruct` would"),
                    );
                }
            }
            if !sol.back_fitted {
                row.error_nm[1] = f64::NAN;
                row.reported_nm[1] = f64::NAN;
                row.note = join_note(
                    &row.note,
                    "no back reflection resolved: back not reconstructed",
                );
            }
        }
        Err(e) => row.note = format!("stopped: {e}"),
    }
    row
}

/// `a` and `b` as one note.
fn join_note(a: &str, b: &str) -> String {
    if a.is_empty() {
        b.to_string()
    } else {
        format!("{a}; {b}")
    }
}

fn write_outputs(rows: &[Row], args: &TradeoffArgs) -> anyhow::Result<()> {
    let mut csv = String::from(
        "frames_per_direction,terms,max_iter,s1_found,s2_found,front_err_nm,back_err_nm,\
         front_reported_nm,back_reported_nm,spectral_s,surfaces_s,acquisition_s,\
         front_predicted_nm,back_predicted_nm,designed,note\n",
    );
    let mut md = String::from(
        "| frames/dir | terms | max iter | S1 / S2 found | front error (nm) | back error (nm) | \
         reported σ front / back (nm) | spectral (s) | surfaces (s) | acquisition (s) | \
         predicted front / back (nm) | note |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        writeln!(
            csv,
            "{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.2},{:.4},{:.4},{},{}",
            r.frames,
            r.terms,
            r.max_iter,
            r.found[0],
            r.found[1],
            r.error_nm[0],
            r.error_nm[1],
            r.reported_nm[0],
            r.reported_nm[1],
            r.spectral_s,
            r.surfaces_s,
            r.acquisition_s,
            r.predicted_nm[0],
            r.predicted_nm[1],
            r.designed,
            r.note.replace(',', ";")
        )?;
        writeln!(
            md,
            "| {} | {} | {} | {} / {} | {:.2} | {:.2} | {:.2} / {:.2} | {:.2} | {:.2} | {:.1} | {:.2} / {:.2} | {} |",
            r.frames,
            r.terms,
            r.max_iter,
            r.found[0],
            r.found[1],
            r.error_nm[0],
            r.error_nm[1],
            r.reported_nm[0],
            r.reported_nm[1],
            r.spectral_s,
            r.surfaces_s,
            r.acquisition_s,
            r.predicted_nm[0],
            r.predicted_nm[1],
            r.note
        )?;
    }
    let write = |name: &str, text: &str| {
        let p = args.out.join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
    };
    write("tradeoff.csv", &csv)?;
    write("tradeoff.md", &md)?;
    plot(rows, args)?;
    plot_time(rows, args)?;
    println!("{md}");
    println!(
        "wrote {} and tradeoff-time.png",
        args.out.join("tradeoff.{csv,md,png}").display()
    );
    Ok(())
}

/// Error (front and back) and compute time against frames, one series per
/// term count at the largest iteration limit.
fn plot(rows: &[Row], args: &TradeoffArgs) -> anyhow::Result<()> {
    let it = args.max_iter.iter().copied().max().unwrap_or(30);
    let mut labels = Vec::new();
    let mut data: Vec<[Vec<(f64, f64)>; 3]> = Vec::new();
    for &terms in &args.terms {
        let pick = |f: &dyn Fn(&Row) -> f64| -> Vec<(f64, f64)> {
            rows.iter()
                .filter(|r| r.terms == terms && r.max_iter == it && !r.designed)
                .map(|r| ((2 * r.frames) as f64, f(r)))
                .collect()
        };
        labels.push(format!("{terms} terms"));
        data.push([
            pick(&|r| r.error_nm[0]),
            pick(&|r| r.error_nm[1]),
            pick(&|r| r.spectral_s + r.surfaces_s),
        ]);
    }
    let series = |k: usize| -> Vec<Series> {
        labels
            .iter()
            .zip(&data)
            .map(|(l, d)| Series {
                label: l,
                points: &d[k],
            })
            .collect()
    };
    let (s0, s1, s2) = (series(0), series(1), series(2));
    let panel = |title, y, series, log_y| Panel {
        title,
        x_label: "frames (both directions)",
        y_label: y,
        log_x: true,
        log_y,
        series,
    };
    line_plot_png(
        &args.out.join("tradeoff.png"),
        &[
            panel("Front surface error", "RMS error (nm)", &s0, true),
            panel("Back surface error", "RMS error (nm)", &s1, true),
            panel("Compute time", "seconds (spectral + surfaces)", &s2, true),
        ],
    )?;
    Ok(())
}

/// Error against acquisition time (the planner's timing), front and back:
/// the uniform family and the designed schedules, achieved and their
/// Cramér–Rao bound, at the largest term count and iteration limit.
fn plot_time(rows: &[Row], args: &TradeoffArgs) -> anyhow::Result<()> {
    let it = args.max_iter.iter().copied().max().unwrap_or(30);
    let terms = args.terms.iter().copied().max().unwrap_or(36);
    let pick = |designed: bool, f: &dyn Fn(&Row) -> f64| -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.terms == terms && r.max_iter == it && r.designed == designed)
            .map(|r| (r.acquisition_s, f(r)))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    };
    // The bound only where the planner says the stage measures the
    // schedule: elsewhere it is no prediction of what will be achieved.
    let bound = |r: &Row, k: usize| {
        if r.measurable {
            r.predicted_nm[k]
        } else {
            f64::NAN
        }
    };
    let data: Vec<[Vec<(f64, f64)>; 4]> = (0..2)
        .map(|k| {
            [
                pick(false, &|r| r.error_nm[k]),
                pick(false, &|r| bound(r, k)),
                pick(true, &|r| r.error_nm[k]),
                pick(true, &|r| bound(r, k)),
            ]
        })
        .collect();
    let labels = [
        "uniform, achieved",
        "uniform, bound",
        "designed, achieved",
        "designed, bound",
    ];
    let series = |k: usize| -> Vec<Series> {
        labels
            .iter()
            .zip(&data[k])
            .map(|(l, d)| Series {
                label: l,
                points: d,
            })
            .collect()
    };
    let (s0, s1) = (series(0), series(1));
    let panel = |title, series| Panel {
        title,
        x_label: "acquisition time (s)",
        y_label: "RMS error (nm)",
        log_x: true,
        log_y: true,
        series,
    };
    line_plot_png(
        &args.out.join("tradeoff-time.png"),
        &[
            panel("Front surface error against time", &s0),
            panel("Back surface error against time", &s1),
        ],
    )?;
    Ok(())
}
