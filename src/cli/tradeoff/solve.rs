//! The simulated measurement of one schedule: its frames rendered on the
//! fly (no disk), the spectral stage with `mfd reconstruct`'s quality pass,
//! and the surfaces by the default estimator, scored against the truth.

use std::time::Instant;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::TracedView;
use mfd::optics::zernike::ZernikeSurface;
use mfd::pipeline::{surfaces_from_frames, DirectReport, Estimator};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{Falloff, Renderer, SimParams};
use mfd::solve::spectral::{SpectralConfig, SpectralMaps, SpectralSolver};
use mfd::solve::surfaces::lm::LmOptions;
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::{SurfaceOptions, SurfaceSolution};

use super::row::{join_note, Row};

/// How the frames are rendered: the read noise (fraction of full scale)
/// and what the falloff acts on.
#[derive(Clone, Copy)]
pub(super) struct Render {
    pub(super) noise: f64,
    pub(super) falloff: Falloff,
}

/// The uniform family: τ from 0.5 in steps of 0.5 to 0.5 n, n frames per direction.
pub(super) fn uniform(n: usize) -> Schedule {
    Schedule {
        tau_start: 0.5,
        tau_stop: 0.5 * n as f64,
        tau_step: 0.5,
        ..Schedule::default()
    }
}

/// Renders `frames` on the fly and runs the spectral solver.
pub(super) fn solve_frames(
    station: &Station,
    view: &TracedView,
    frames: &[FrameInfo],
    it: usize,
    render: Render,
    seed: u64,
) -> anyhow::Result<Solved> {
    let params = SimParams {
        noise_frac: render.noise,
        seed,
        falloff: render.falloff,
        ..SimParams::default()
    };
    let mut cam = Renderer::new(view, &station.screen, params)?;
    let config = SpectralConfig {
        max_iter: it.max(1),
        ..SpectralConfig::default()
    };
    let mut solver = SpectralSolver::new(station, frames, config)?;
    solver.push_made(|k, buf| {
        let f = &frames[k];
        let p = mfd::acquire::patterns::Pattern {
            direction_deg: f.direction_deg,
            tau: f.tau,
            phase_rad: f.phase_rad,
        };
        cam.render(&p, k as u64, buf);
    })?;
    checked(solver, station)
}

/// A spectral stage that has run: the solver (its schedule and prior,
/// which the surface-domain fit needs) and its maps.
pub(super) struct Solved {
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

/// Renders the uniform schedule of `n` frames per direction on the fly (no
/// disk, noise seed `seed + n`) and runs the spectral solver: the frames
/// of [`uniform`], through [`solve_frames`].
pub(super) fn spectral(
    station: &Station,
    view: &TracedView,
    n: usize,
    it: usize,
    render: Render,
    seed: u64,
) -> anyhow::Result<Solved> {
    let frames = FrameInfo::from_patterns(&uniform(n).patterns());
    solve_frames(station, view, &frames, it, render, seed + n as u64)
}

/// The surfaces of a solved stage, by `mfd reconstruct`'s default
/// estimator (`auto`: the surface-domain fit where the reflections are
/// closer than its rule, or where the per-pixel route measures nothing),
/// against the truth.
pub(super) fn surfaces(
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
        Ok((_, sol, direct)) => score(&mut row, &sol, direct.as_ref(), truth),
        Err(e) => row.note = format!("stopped: {e}"),
    }
    row
}

/// Fills `row` from a solution: the errors against the truth and the
/// reported σ, NaN for what `mfd reconstruct` would withhold or did not
/// fit, and the notes saying so.
fn score(
    row: &mut Row,
    sol: &SurfaceSolution,
    direct: Option<&DirectReport>,
    truth: (&ZernikeSurface, &ZernikeSurface),
) {
    if direct.is_some() {
        row.note = "surface-domain fit".into();
    }
    // What `mfd reconstruct` would withhold is not counted as
    // measured (`pipeline::withheld`'s rules): both surfaces where
    // the surface-domain fit did not converge, a surface whose
    // expected error is at least its fitted RMS.
    let unconverged = direct.is_some_and(|d| !d.converged);
    let withheld = [false, true].map(|back| {
        let f = figures(sol, back);
        unconverged || (f.error_rms_nm > 0.0 && f.error_rms_nm >= f.rms_nm)
    });
    row.error_nm = [
        rms_difference_nm(sol.front.coefficients_nm(), truth.0.coefficients_nm()),
        rms_difference_nm(sol.back.coefficients_nm(), truth.1.coefficients_nm()),
    ];
    row.reported_nm = [
        figures(sol, false).error_rms_nm,
        figures(sol, true).error_rms_nm,
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
