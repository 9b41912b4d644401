//! The reconstruction pipeline as one library call: from an acquisition,
//! a streamed spectral solver, or screen points, through the spectral stage
//! and the surface solvers, to the files of a result folder.
//!
//! ```text
//! Input::Acquisition ─► spectral solver ─┐
//! Input::Streamed (frames already in) ───┼─► SpectralMaps ─► surface solvers ─► Reconstruction
//! Input::ScreenPoints ───────────────────────────────────────┘                   └─► write(DIR)
//! ```
//!
//! `mfd reconstruct`, `mfd measure`, the tests and any server call
//! [`reconstruct`]; the command line only parses arguments and prints.

use std::time::Instant;

use crate::acquire::acquisition::Acquisition;
use crate::budget::Budget;
use crate::optics::station::{Dof, Station, StationUncertainty};
use crate::report::summary::Summary;
use crate::solve::spectral::{FeedError, SpectralConfig, SpectralMaps, SpectralSolver};
use crate::solve::surfaces::convergence::Convergence;
use crate::solve::surfaces::{
    reconstruct as solve_surfaces, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
    Uncertainty,
};

pub mod consistency;
mod estimator;
pub mod result_dir;
mod result_files;
mod screen_points;
mod station_uncertainty;
pub mod wedge;

pub use crate::solve::direct::DirectReport;
mod error;

pub use consistency::{Consistency, Limits, DEFAULT_MAX_DEPARTURE_NM};
pub use error::PipelineError;
pub use estimator::{surfaces_from_frames, withheld, Estimator};
pub use result_dir::{InputFile, Inputs, Staged};
pub use result_files::{surfaces_file, BACK_NOT_RECONSTRUCTED};
pub use screen_points::{PointUncertainty, ScreenPoints};

use crate::budget::assemble::budget;
use crate::budget::refine::{refine, RefineError, Refined};
use crate::solve::surfaces::station_error::with_station;

pub use station_uncertainty::{
    find_station_uncertainty, FoundUncertainty, UncertaintySource, STATION_UNCERTAINTY_FILE,
};

/// Side of the height-map grids written beside `surfaces.json`, pixels.
pub const HEIGHT_GRID: usize = 256;

/// What a reconstruction starts from.
pub enum Input<'a> {
    /// An acquisition folder's frames, read in order.
    Acquisition(&'a mut Acquisition),
    /// A spectral solver that has taken every frame (a live measurement's).
    Streamed(&'a mut SpectralSolver),
    /// Screen points: only the surface stage runs.
    ScreenPoints(ScreenPoints),
}

/// What to run and how.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The spectral stage's configuration (unused for screen points).
    pub spectral: SpectralConfig,
    /// The surface stage's options; `None` stops after the spectral stage.
    pub surfaces: Option<SurfaceOptions>,
    /// The station's uncertainty: when given, the surface stage also
    /// computes the error budget (`crate::budget::assemble::budget`), and
    /// every reported σ includes the station's part; when `None` the
    /// geometry counts as exact and the results say so.
    pub station_uncertainty: Option<StationUncertainty>,
    /// Degrees of freedom estimated jointly with the surfaces, the station
    /// uncertainty their prior ([`crate::budget::refine`]); each needs a σ
    /// there. Empty: the station is taken as given.
    pub refine: Vec<Dof>,
    /// Which estimator makes the surfaces from the frames.
    pub estimator: Estimator,
    /// A surface whose expected RMS error exceeds this (nm) is reported as
    /// not reconstructed, with the reason; `None`: only the rule of
    /// [`withheld`] (an expected error as large as the surface).
    pub max_expected_nm: Option<f64>,
    /// The checks of the spectral stage's points against the noise and
    /// the station ([`consistency`]).
    pub limits: Limits,
    /// The wavelength of the transmitted wavefront's figures in waves, nm;
    /// `None`: [`crate::report::figures::DEFAULT_WAVELENGTH_NM`].
    pub wavelength_nm: Option<f64>,
    /// Start from the station's wedge without looking in the frames for
    /// the back reflection first ([`wedge::check_wedge`]).
    pub skip_wedge_search: bool,
}

/// The spectral stage's result.
#[derive(Debug)]
pub struct SpectralStage {
    /// Per-pixel screen points, covariance and quality maps.
    pub maps: SpectralMaps,
    /// Pixels fitted (those the station predicts to see the element).
    pub fitted_pixels: usize,
    /// Seconds spent reading the frames (0 for a streamed solver).
    pub read_s: f64,
    /// Seconds of the solve after the last frame.
    pub solve_s: f64,
    /// The points checked against the noise and the station.
    pub consistency: Consistency,
    /// The wedge the frames show, where it was looked for
    /// ([`wedge::check_wedge`]); when `used_found`, every stage started
    /// from it instead of the station's.
    pub wedge: Option<wedge::WedgeCheck>,
}

/// The surface stage's result.
#[derive(Debug)]
pub struct SurfaceStage {
    /// The surfaces with their covariance.
    pub solution: SurfaceSolution,
    /// Its figures (`summary.json`).
    pub summary: Summary,
    /// The error budget of the solution (sensitivity of every coefficient
    /// to every degree of freedom with a σ, noise, total covariance), when
    /// a station uncertainty was given.
    pub budget: Option<Budget>,
    /// The degrees of freedom measured with the surfaces (`Options::refine`):
    /// the refined station, the estimates; the solution and the budget
    /// above are those on the refined station.
    pub refined: Option<Refined>,
    /// The surface-domain fit's account, when it made the surfaces.
    pub direct: Option<DirectReport>,
    /// Why a surface (front, back) is reported as not reconstructed, where
    /// it is ([`withheld`]).
    pub withheld: [Option<String>; 2],
}

/// A reconstruction: whichever stages ran.
#[derive(Debug)]
pub struct Reconstruction {
    /// The spectral stage (absent when starting from screen points).
    pub spectral: Option<SpectralStage>,
    /// The surface stage: absent when not asked for, an error when it could
    /// not run (the spectral maps are still there to be written).
    pub surfaces: Option<Result<SurfaceStage, SurfaceError>>,
    /// What the result was made from (set by the caller, who knows the
    /// paths); written as `inputs.json` and into `summary.json`.
    pub inputs: Option<Inputs>,
}

/// Runs the stages `options` asks for on `input`. `progress(done, total)`
/// is called after each frame read from an acquisition.
///
/// A failing surface stage is not an error of this call: it is returned in
/// [`Reconstruction::surfaces`], so the spectral maps can still be written.
///
/// # Errors
/// [`PipelineError`] when reading the frames or the spectral stage fails.
pub fn reconstruct(
    input: Input<'_>,
    station: &Station,
    options: &Options,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Reconstruction, PipelineError> {
    // Every stage works in the element's own frame (station v2's pose);
    // the surfaces come out in it, as the spec reports them.
    let mut frame_station = station.element_frame();
    let owned;
    let (first, solver): (First, Option<&SpectralSolver>) = match input {
        Input::Acquisition(acq) => {
            let (stage, solver, used) = read_acquisition(acq, &frame_station, options, progress)?;
            // The wedge the frames show, where the station's was not it.
            frame_station = used;
            owned = solver;
            (First::Spectral(Box::new(stage)), Some(&owned))
        }
        Input::Streamed(solver) => (
            First::Spectral(Box::new(spectral_stage(
                solver,
                &frame_station,
                options,
                0.0,
                None,
            )?)),
            Some(&*solver),
        ),
        Input::ScreenPoints(points) => (First::Points(points), None),
    };
    let station = &frame_station;
    let mut surfaces = options
        .surfaces
        .as_ref()
        .map(|opts| surface_stage(&first, solver, station, opts, options));
    if let (Some(Ok(stage)), First::Spectral(s)) = (&mut surfaces, &first) {
        stage.summary.consistency = Some(s.consistency.clone());
        stage
            .summary
            .convergence
            .insert(0, spectral_convergence(&s.maps));
    }
    let spectral = match first {
        First::Spectral(s) => Some(*s),
        First::Points(_) => None,
    };
    Ok(Reconstruction {
        spectral,
        surfaces,
        inputs: None,
    })
}

/// The spectral stage's per-pixel fits in `summary.json`'s `convergence`:
/// how many stopped at their iteration limit (flagged `NOT_CONVERGED` in
/// `flags.npy`). Each such pixel's point carries its own σ and faces the
/// surface fit's outlier rule, so they are counted and said, not a flag on
/// the result.
fn spectral_convergence(maps: &crate::solve::spectral::SpectralMaps) -> Convergence {
    use crate::solve::spectral::PixelFlags;
    let n = maps
        .pixels
        .iter()
        .filter(|p| {
            p.flags.intersects(PixelFlags::NOT_CONVERGED)
                && !p.flags.intersects(PixelFlags::NO_DATA)
        })
        .count();
    let mut c = Convergence::new(
        "spectral per-pixel fits",
        if n == 0 {
            "every pixel's own stopping rule".into()
        } else {
            "iteration limit (or a singular step)".into()
        },
        n == 0,
        None,
        false,
    );
    c.pixels = Some(n);
    c.flags_result = false;
    c
}

/// Reads every frame of `acq` into a new spectral solver, calling
/// `progress(done, total)` after each, and runs the spectral stage; returns
/// the stage, the solver (the surface-domain estimator fits its frames) and
/// the station every stage started from: `station`, or it with the wedge
/// the frames show ([`wedge::check_wedge`]).
fn read_acquisition(
    acq: &mut Acquisition,
    station: &Station,
    options: &Options,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(SpectralStage, SpectralSolver, Station), PipelineError> {
    crate::acquire::acquisition::check_against_station(acq, station)?;
    let t0 = Instant::now();
    acq.check_resolution(station.camera.width, station.camera.height)?;
    let (station, wedge) = if options.skip_wedge_search {
        (station.clone(), None)
    } else {
        wedge::check_wedge(acq, station, &options.spectral)?
    };
    let station = &station;
    let mut solver = SpectralSolver::new(station, acq.frames(), options.spectral.clone())?;
    let total = acq.frames().len();
    let max_count = solver
        .push_acquisition(acq, total, progress)
        .map_err(FeedError::into_cause::<PipelineError>)?;
    let mut stage = spectral_stage(
        &mut solver,
        station,
        options,
        t0.elapsed().as_secs_f64(),
        Some(max_count),
    )?;
    stage.wedge = wedge;
    Ok((stage, solver, station.clone()))
}

/// Where the surface stage's screen points come from.
enum First {
    // Boxed: the stage (maps' handles, the wedge check) dwarfs the points' handle.
    Spectral(Box<SpectralStage>),
    Points(ScreenPoints),
}

/// The surface stage on the spectral stage's maps (or the frames, by the
/// estimator asked for) or on screen points: the surfaces, refined with the
/// station where asked, their error budget, summary and withheld surfaces.
fn surface_stage(
    first: &First,
    solver: Option<&SpectralSolver>,
    station: &Station,
    opts: &SurfaceOptions,
    options: &Options,
) -> Result<SurfaceStage, SurfaceError> {
    let (uncertainty, refine) = (options.station_uncertainty.as_ref(), &options.refine[..]);
    let t = Instant::now();
    let (obs, mut solution, direct) = first_surfaces(first, solver, station, opts, options)?;
    let refined = match uncertainty {
        Some(u) if !refine.is_empty() => {
            let r = refine_station(&obs, station, u, refine, &solution, opts)?;
            solution = r.solution.clone();
            Some(r)
        }
        None if !refine.is_empty() => {
            return Err(SurfaceError::Input {
                what: "--refine",
                problem: "a refined degree of freedom needs a prior: give the station's \
                          uncertainty (--uncertainty, or station_uncertainty.toml beside \
                          the station)"
                    .into(),
            })
        }
        _ => None,
    };
    let (obs, station, uncertainty) = match &refined {
        Some(r) => (
            with_station(&obs, &r.station),
            &r.station,
            Some(&r.uncertainty),
        ),
        None => (obs, station, uncertainty),
    };
    let budget = match uncertainty {
        Some(u) => Some(budget(&obs, station, u, &solution, opts)?),
        None => None,
    };
    let mut summary = stage_summary(
        &obs,
        &solution,
        t.elapsed().as_secs_f64(),
        budget.as_ref(),
        refined.as_ref(),
        direct.as_ref(),
    );
    let withheld = withheld(&summary, direct.as_ref(), options.max_expected_nm);
    summary.withheld = withheld.clone();
    summary.figures = crate::report::figures::joint::of_solution(
        &solution,
        budget.as_ref(),
        station,
        options
            .wavelength_nm
            .unwrap_or(crate::report::figures::DEFAULT_WAVELENGTH_NM),
        &withheld,
    );
    Ok(SurfaceStage {
        solution,
        summary,
        budget,
        refined,
        direct,
        withheld,
    })
}

/// The surfaces as first solved on the station given: from the frames by
/// the estimator asked for where a solver holds them, else from the
/// spectral maps' points or the screen points given.
fn first_surfaces(
    first: &First,
    solver: Option<&SpectralSolver>,
    station: &Station,
    opts: &SurfaceOptions,
    options: &Options,
) -> Result<(Observations, SurfaceSolution, Option<DirectReport>), SurfaceError> {
    Ok(match (first, solver) {
        (First::Spectral(s), Some(solver)) => {
            estimator::surfaces_from_frames(solver, &s.maps, station, opts, options.estimator)?
        }
        (First::Spectral(s), None) => {
            let cov = s.maps.screen_cov();
            let obs =
                Observations::from_maps(station, &s.maps.screen_coords(), Uncertainty::Cov(&cov))?;
            let sol = solve_surfaces(&obs, station, opts)?;
            (obs, sol, None)
        }
        (First::Points(p), _) => {
            let obs = Observations::from_maps(station, &p.coords, p.uncertainty())?;
            let sol = solve_surfaces(&obs, station, opts)?;
            (obs, sol, None)
        }
    })
}

/// The summary of `solution`, solved from `obs` in `seconds`, with the
/// station's part of `budget`, the estimates of `refined` and the account
/// of the surface-domain fit, where each exists.
fn stage_summary(
    obs: &Observations,
    solution: &SurfaceSolution,
    seconds: f64,
    budget: Option<&Budget>,
    refined: Option<&Refined>,
    direct: Option<&DirectReport>,
) -> Summary {
    let mut summary = Summary::new(obs, solution, seconds);
    if let Some(b) = budget {
        summary = summary.with_budget(b);
    }
    if let Some(r) = refined {
        summary = summary.with_refined(r);
    }
    if let Some(d) = direct {
        summary = summary.with_direct(d);
    }
    summary
}

/// [`crate::budget::refine::refine`] with the solution's numbers of terms
/// fixed; a degree of freedom without a prior is an input error.
fn refine_station(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    dofs: &[Dof],
    solution: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<Refined, SurfaceError> {
    let terms = solution
        .front
        .coefficients_nm()
        .len()
        .max(solution.back.coefficients_nm().len());
    let fixed = SurfaceOptions {
        terms: Some(terms),
        ..opts.clone()
    };
    refine(obs, station, uncertainty, dofs, &fixed).map_err(|e| match e {
        RefineError::Surface(e) => e,
        e @ RefineError::NoPrior { .. } => SurfaceError::Input {
            what: "--refine",
            problem: e.to_string(),
        },
    })
}

/// The spectral stage's fit, its points checked against the noise and the
/// station, and (when it measured nothing) the reason in words, before the
/// surface stage fails on the absence.
fn spectral_stage(
    solver: &mut SpectralSolver,
    station: &Station,
    options: &Options,
    read_s: f64,
    max_count: Option<u16>,
) -> Result<SpectralStage, PipelineError> {
    let t = Instant::now();
    let mut maps = solver.solve()?;
    let consistency = consistency::check(
        &mut maps,
        solver.prior(),
        station,
        solver.design(),
        options.limits,
    );
    if let Some(why) =
        consistency::why_nothing(&maps, solver.candidate_pixels(), max_count, solver.design())
    {
        // The surface stage would fail on the absence; without one the
        // (empty) maps are the result, and the reason a warning.
        if options.surfaces.is_some() {
            return Err(PipelineError::NoSignal(why));
        }
        log::warn!("{why}");
    }
    Ok(SpectralStage {
        maps,
        fitted_pixels: solver.candidate_pixels(),
        read_s,
        solve_s: t.elapsed().as_secs_f64(),
        consistency,
        wedge: None,
    })
}
