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

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::acquire::acquisition::{Acquisition, AcquisitionError};
use crate::budget::Budget;
use crate::formats::npy::{self, NpyError};
use crate::formats::surfaces_file::{
    SurfaceCoefficients, SurfaceEntry, SurfacesFile, SurfacesFileError, ZernikeSpec,
};
use crate::optics::station::{Dof, Station, StationUncertainty, UncertaintyError};
use crate::plot::PlotError;
use crate::report::pictures;
use crate::report::summary::Summary;
use crate::solve::spectral::{SpectralConfig, SpectralError, SpectralMaps, SpectralSolver};
use crate::solve::surfaces::report::height_grid;
use crate::solve::surfaces::{
    reconstruct as solve_surfaces, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
    Uncertainty,
};

pub mod consistency;
mod estimator;
pub mod result_dir;
mod station_uncertainty;

pub use crate::solve::direct::DirectReport;
pub use consistency::{Consistency, Limits, DEFAULT_MAX_DEPARTURE_NM};
pub use estimator::{surfaces_from_frames, withheld, Estimator};
pub use result_dir::{InputFile, Inputs, Staged};

use crate::budget::assemble::budget;
use crate::budget::refine::{refine, RefineError, Refined};
use crate::solve::surfaces::station_error::with_station;

pub use station_uncertainty::{
    find_station_uncertainty, FoundUncertainty, UncertaintySource, STATION_UNCERTAINTY_FILE,
};

/// Side of the height-map grids written beside `surfaces.json`, pixels.
pub const HEIGHT_GRID: usize = 256;

/// Errors of the pipeline: which stage or file failed, with its cause.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Reading the acquisition failed.
    #[error(transparent)]
    Acquisition(#[from] AcquisitionError),
    /// The spectral stage failed.
    #[error(transparent)]
    Spectral(#[from] SpectralError),
    /// An NPY array could not be read or written.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// An array does not fit the station.
    #[error("{path}: shape {found:?}, expected {expected:?} ({what}) for the station's camera")]
    Shape {
        /// The file.
        path: PathBuf,
        /// Its shape.
        found: Vec<usize>,
        /// The shape the station implies.
        expected: Vec<usize>,
        /// What the axes are.
        what: &'static str,
    },
    /// `surfaces.json` could not be written.
    #[error(transparent)]
    SurfacesFile(#[from] SurfacesFileError),
    /// A picture could not be drawn or written.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// A file or folder of the result could not be written.
    #[error("writing {path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A result folder cannot be used (a file, or a folder that is not
    /// an mfd result).
    #[error("{path}: {problem}")]
    Output {
        /// The folder.
        path: PathBuf,
        /// Why.
        problem: String,
    },
    /// The data hold nothing the stages can measure: which pixels were
    /// looked at and what was found, in words.
    #[error("{0}")]
    NoSignal(String),
    /// A station uncertainty file could not be read.
    #[error(transparent)]
    Uncertainty(#[from] UncertaintyError),
    /// The refined station could not be written.
    #[error(transparent)]
    Station(#[from] crate::optics::station::StationError),
    /// A station uncertainty file is that of another station.
    #[error(
        "{uncertainty}: its `station` field names \"{named}\" ({resolved}), but the station \
         used is {station}, a different station: give the uncertainty of this station \
         (--uncertainty), or the station it belongs to (--station)"
    )]
    UncertaintyOfAnotherStation {
        /// The uncertainty file.
        uncertainty: PathBuf,
        /// What its `station` field says.
        named: String,
        /// That, relative to the uncertainty file's folder.
        resolved: PathBuf,
        /// The station file used.
        station: PathBuf,
    },
    /// `summary.json` could not be serialised.
    #[error("{path}: {source}")]
    Json {
        /// The path.
        path: PathBuf,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
}

/// The uncertainty of screen points handed to the surface stage.
#[derive(Debug, Clone)]
pub enum PointUncertainty {
    /// `[rows, cols, 4, 4]`: covariance of u1, v1, u2, v2 per pixel, px².
    Covariance(Vec<f64>),
    /// `[rows, cols, 2, 2]`: standard deviations, px.
    Std(Vec<f64>),
    /// None known: the residuals set the scale.
    Unknown,
}

/// Screen points of every camera pixel, `[rows, cols, 2, 2]` (spec layout),
/// with their uncertainty.
#[derive(Debug, Clone)]
pub struct ScreenPoints {
    /// u, v of front and back, screen px, NaN where not found.
    pub coords: Vec<f64>,
    /// Their uncertainty.
    pub uncertainty: PointUncertainty,
}

impl ScreenPoints {
    /// Reads `screen_coords.npy` at `coords` and its uncertainty: `std`
    /// (`[rows, cols, 2, 2]`) when given, else `screen_cov.npy` or
    /// `screen_std.npy` beside it when one exists, else none. Returns the
    /// file the uncertainty came from.
    ///
    /// # Errors
    /// [`PipelineError::Npy`] for unreadable files, [`PipelineError::Shape`]
    /// when an array does not fit the station's camera.
    pub fn load(
        coords: &Path,
        std: Option<&Path>,
        station: &Station,
    ) -> Result<(ScreenPoints, Option<PathBuf>), PipelineError> {
        let (rows, cols) = (
            station.camera.height as usize,
            station.camera.width as usize,
        );
        let read = |path: &Path, k: usize| -> Result<Vec<f64>, PipelineError> {
            let expected = vec![rows, cols, k, k];
            let (found, data) = npy::read_f64(path)?;
            if found != expected {
                let what = if k == 2 {
                    "rows, columns, reflection, u/v"
                } else {
                    "rows, columns, covariance of u1, v1, u2, v2"
                };
                let path = path.to_path_buf();
                return Err(PipelineError::Shape {
                    path,
                    found,
                    expected,
                    what,
                });
            }
            Ok(data)
        };
        let beside = |name: &str| Some(coords.with_file_name(name)).filter(|p| p.exists());
        let (source, is_cov) = match std {
            Some(p) => (Some(p.to_path_buf()), false),
            None => match beside("screen_cov.npy") {
                Some(p) => (Some(p), true),
                None => (beside("screen_std.npy"), false),
            },
        };
        let uncertainty = match &source {
            None => PointUncertainty::Unknown,
            Some(p) if is_cov => PointUncertainty::Covariance(read(p, 4)?),
            Some(p) => PointUncertainty::Std(read(p, 2)?),
        };
        let points = ScreenPoints {
            coords: read(coords, 2)?,
            uncertainty,
        };
        Ok((points, source))
    }
}

impl ScreenPoints {
    /// The uncertainty as the surface stage takes it.
    fn uncertainty(&self) -> Uncertainty<'_> {
        match &self.uncertainty {
            PointUncertainty::Covariance(c) => Uncertainty::Cov(c),
            PointUncertainty::Std(s) => Uncertainty::Std(s),
            PointUncertainty::Unknown => Uncertainty::Unknown,
        }
    }
}

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
    let station = &station.element_frame();
    let owned;
    let (first, solver): (First, Option<&SpectralSolver>) = match input {
        Input::Acquisition(acq) => {
            crate::acquire::acquisition::check_against_station(acq, station)?;
            let t0 = Instant::now();
            acq.check_resolution(station.camera.width, station.camera.height)?;
            let mut solver = SpectralSolver::new(station, acq.frames(), options.spectral.clone())?;
            let total = acq.frames().len();
            let mut frame = Vec::new();
            let mut max_count = 0u16;
            for k in 0..total {
                let index = acq.frames()[k].index;
                acq.read_frame(index, &mut frame)?;
                max_count = frame.iter().copied().fold(max_count, u16::max);
                solver.push_frame(index, &frame)?;
                progress(k + 1, total);
            }
            let stage = spectral_stage(
                &mut solver,
                station,
                options,
                t0.elapsed().as_secs_f64(),
                Some(max_count),
            )?;
            owned = solver;
            (First::Spectral(stage), Some(&owned))
        }
        Input::Streamed(solver) => (
            First::Spectral(spectral_stage(solver, station, options, 0.0, None)?),
            Some(&*solver),
        ),
        Input::ScreenPoints(points) => (First::Points(points), None),
    };
    let mut surfaces = options
        .surfaces
        .as_ref()
        .map(|opts| surface_stage(&first, solver, station, opts, options));
    if let (Some(Ok(stage)), First::Spectral(s)) = (&mut surfaces, &first) {
        stage.summary.consistency = Some(s.consistency.clone());
    }
    let spectral = match first {
        First::Spectral(s) => Some(s),
        First::Points(_) => None,
    };
    Ok(Reconstruction {
        spectral,
        surfaces,
        inputs: None,
    })
}

/// Where the surface stage's screen points come from.
enum First {
    Spectral(SpectralStage),
    Points(ScreenPoints),
}

fn surface_stage(
    first: &First,
    solver: Option<&SpectralSolver>,
    station: &Station,
    opts: &SurfaceOptions,
    options: &Options,
) -> Result<SurfaceStage, SurfaceError> {
    let (uncertainty, refine) = (options.station_uncertainty.as_ref(), &options.refine[..]);
    let t = Instant::now();
    let (obs, mut solution, direct) = match (first, solver) {
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
    };
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
    let mut summary = Summary::new(&obs, &solution, t.elapsed().as_secs_f64());
    if let Some(b) = &budget {
        summary = summary.with_budget(b);
    }
    if let Some(r) = &refined {
        summary = summary.with_refined(r);
    }
    if let Some(d) = &direct {
        summary = summary.with_direct(d);
    }
    let withheld = withheld(&summary, direct.as_ref(), options.max_expected_nm);
    summary.withheld = withheld.clone();
    Ok(SurfaceStage {
        solution,
        summary,
        budget,
        refined,
        direct,
        withheld,
    })
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
    if let Some(why) = consistency::why_nothing(&maps, solver.candidate_pixels(), max_count) {
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
    })
}

impl Reconstruction {
    /// Writes every result that exists into `out` (created if needed): the
    /// spectral maps (`screen_coords.npy` and the quality maps), and for a
    /// surface solution `surfaces.json`, `{front,back}_height_nm.npy`, the
    /// pictures and `summary.json`. Returns the files written.
    ///
    /// # Errors
    /// [`PipelineError`] naming the file that could not be written.
    pub fn write(&self, out: &Path) -> Result<Vec<PathBuf>, PipelineError> {
        std::fs::create_dir_all(out).map_err(|source| PipelineError::Io {
            path: out.to_path_buf(),
            source,
        })?;
        let mut written = Vec::new();
        let inputs = self.inputs.clone().unwrap_or_default();
        let path = out.join(result_dir::INPUTS_FILE);
        write_json(&path, &inputs)?;
        written.push(path);
        if let Some(s) = &self.spectral {
            s.maps.write(out)?;
            written.push(out.join("screen_coords.npy"));
            let path = out.join("consistency.json");
            write_json(&path, &s.consistency)?;
            written.push(path);
        }
        if let Some(Ok(stage)) = &self.surfaces {
            let mut summary = stage.summary.clone();
            summary.inputs = self.inputs.clone();
            written.extend(write_surfaces(out, stage, &summary)?);
        }
        Ok(written)
    }
}

/// The surface stage's files in `out`.
fn write_surfaces(
    out: &Path,
    stage: &SurfaceStage,
    summary: &Summary,
) -> Result<Vec<PathBuf>, PipelineError> {
    let sol = &stage.solution;
    let mut written = vec![out.join("surfaces.json")];
    surfaces_file(stage).save(&written[0])?;
    if let Some(r) = &stage.refined {
        // The refined station and its uncertainty, for the next measurement.
        let path = out.join("station_refined.toml");
        r.station.save(&path)?;
        written.push(path);
        let path = out.join("station_refined_uncertainty.toml");
        let mut unc = r.uncertainty.clone();
        unc.station = "station_refined.toml".into();
        unc.save(&path)?;
        written.push(path);
    }
    if let Some(d) = &stage.direct {
        // The surface-domain fit's per-pixel maps: the points its surfaces
        // predict, and each pixel's pull against them (a defect the
        // Zernike model cannot follow shows there).
        let (w, h) = (d.width, d.chi2_map.len() / d.width.max(1));
        let path = out.join("direct_screen_coords.npy");
        npy::write_f64(&path, &[h, w, 2, 2], &d.predicted)?;
        written.push(path);
        let path = out.join("direct_chi2.npy");
        npy::write_f64(&path, &[h, w], &d.chi2_map)?;
        written.push(path);
    }
    // A withheld surface gets no height map or picture.
    let mut surfaces = Vec::new();
    if stage.withheld[0].is_none() {
        surfaces.push(("front", &sol.front, &summary.front));
    }
    if let Some(back) = summary
        .back
        .as_ref()
        .filter(|_| stage.withheld[1].is_none())
    {
        surfaces.push(("back", &sol.back, back));
    }
    for (name, surface, figures) in surfaces {
        let grid = height_grid(surface, HEIGHT_GRID);
        let path = out.join(format!("{name}_height_nm.npy"));
        npy::write_f64(&path, &[HEIGHT_GRID, HEIGHT_GRID], &grid)?;
        written.push(path);
        written.push(pictures::surface(
            out,
            name,
            surface,
            &grid,
            HEIGHT_GRID,
            figures,
        )?);
        let back = name == "back";
        let total = summary
            .station
            .as_ref()
            .and_then(|s| {
                if back {
                    s.back.as_ref()
                } else {
                    Some(&s.front)
                }
            })
            .map(|s| &s.total_std_nm[..]);
        written.extend(pictures::coefficients(out, name, figures, total)?);
    }
    written.extend(pictures::breakdown(out, summary)?);
    let path = out.join("summary.json");
    write_json(&path, summary)?;
    written.push(path);
    Ok(written)
}

/// `value` as pretty JSON in `path`.
fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), PipelineError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| PipelineError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    std::fs::write(path, text + "\n").map_err(|source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Why the back is absent from `surfaces.json` when it was not fitted.
pub const BACK_NOT_RECONSTRUCTED: &str = "no back reflection was measured (no camera pixel \
had a point S2 from the back surface)";

/// `surfaces.json` (`mfd-surfaces/2`) of a surface stage: per surface the
/// coefficients, their 1σ of everything known (noise, and the station's
/// part where a station uncertainty was used) and the expected RMS error;
/// a back that was not reconstructed says why.
pub fn surfaces_file(stage: &SurfaceStage) -> SurfacesFile {
    let (sol, summary) = (&stage.solution, &stage.summary);
    let entry = |surface: &crate::optics::zernike::ZernikeSurface, back: bool| {
        let (std, expected) = summary
            .reported(back)
            .map_or((None, None), |(s, e)| (Some(s.to_vec()), Some(e)));
        SurfaceEntry::Reconstructed(SurfaceCoefficients {
            coefficients_nm: surface.coefficients_nm().to_vec(),
            std_nm: std,
            expected_error_rms_nm: expected,
        })
    };
    let not = |because: &str| SurfaceEntry::NotReconstructed {
        because: Some(because.into()),
    };
    let front = match &stage.withheld[0] {
        Some(why) => not(why),
        None => entry(&sol.front, false),
    };
    let back = match (&stage.withheld[1], sol.back_fitted) {
        (_, false) => not(BACK_NOT_RECONSTRUCTED),
        (Some(why), true) => not(why),
        (None, true) => entry(&sol.back, true),
    };
    SurfacesFile::v2(ZernikeSpec::of(sol.front.basis()), front, back)
}
