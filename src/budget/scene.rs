//! The scene a budget is computed on, before any frame is taken: the
//! station traced through the element's expected surfaces (the screen
//! points every pixel would measure without noise), every pixel's
//! covariance of `(u1, v1, u2, v2)` from the Cramér–Rao bound of the
//! schedule with the simulator's radiometry, and the noise-free
//! reconstruction whose covariance is the imaging-noise term.
//!
//! Also the `mfd-schedule/1` reader's budget form (the reader itself is
//! `acquire::schedule_file`) and the uncertainty from per-degree-of-freedom 1σ
//! values given on a command line.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::acquire::acquisition::FrameInfo;
use crate::optics::station::{Dof, Station, StationUncertainty};
use crate::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use crate::optics::zernike::ZernikeSurface;
use crate::solve::spectral::bound::truth_cov_map_repeated;
use crate::solve::spectral::model::{Design, Repeats};
use crate::solve::surfaces::{
    reconstruct, Observations, SurfaceError, SurfaceOptions, SurfaceSolution, Uncertainty,
};

/// The format tag of a schedule file.
pub const SCHEDULE_FORMAT: &str = crate::acquire::schedule_file::SCHEDULE_FORMAT;

/// What went wrong preparing a budget.
#[derive(Debug, thiserror::Error)]
pub enum BudgetError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A file is not what its format says (the TOML error names the field).
    #[error("{path}: not a valid {format} file: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The format expected.
        format: &'static str,
        /// The TOML error.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// An input (a file's field, a command-line value) holds what is not allowed.
    #[error("{input}: {problem}")]
    Invalid {
        /// Where: `FILE: field`, or the flag, e.g. `--std camera.z_mm=0`.
        input: String,
        /// What is wrong and what to do.
        problem: String,
    },
    /// The expected surfaces could not be read.
    #[error(transparent)]
    Surfaces(#[from] crate::formats::surfaces_file::SurfacesFileError),
    /// A Zernike surface could not be built.
    #[error("the expected surfaces: {0}")]
    Zernike(#[from] crate::optics::zernike::ZernikeError),
    /// The reconstruction of the scene (or of a Monte Carlo draw) failed.
    #[error("reconstructing the budget's scene: {0}")]
    Surface(#[from] SurfaceError),
}

impl crate::outcome::Classify for BudgetError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            BudgetError::Io { source, .. } => crate::outcome::io_outcome(source),
            // An option (`input` names it: `--std camera.q=1`) the budget
            // cannot take is a bad command line; a file's field is input.
            BudgetError::Invalid { input, .. } if input.starts_with("--") => Some(Outcome::Range),
            BudgetError::Parse { .. } | BudgetError::Invalid { .. } => Some(Outcome::Input),
            BudgetError::Surfaces(e) => e.outcome(),
            BudgetError::Zernike(e) => e.outcome(),
            BudgetError::Surface(e) => e.outcome(),
        }
    }
}

fn invalid(input: impl Into<String>, problem: impl Into<String>) -> BudgetError {
    BudgetError::Invalid {
        input: input.into(),
        problem: problem.into(),
    }
}

/// Reads an `mfd-schedule/1` file: its frames in display order
/// ([`crate::acquire::schedule_file`], the one reader).
///
/// # Errors
/// [`BudgetError`] naming the file and the field (`frame[k].tau`, ...).
pub fn load_schedule(path: &Path) -> Result<Vec<FrameInfo>, BudgetError> {
    crate::acquire::schedule_file::load(path)
        .map(|file| file.frames())
        .map_err(schedule_error)
}

/// [`load_schedule`] for `station`: every τ one its screen can show, by
/// the check `mfd simulate`, `measure` and `reconstruct` make
/// ([`crate::acquire::schedule_file::ScheduleFile::check_against_screen`]).
///
/// # Errors
/// As [`load_schedule`]; a τ beyond the screen's Nyquist limit names
/// `frame[k].tau` and the limit.
pub fn load_schedule_for(path: &Path, station: &Station) -> Result<Vec<FrameInfo>, BudgetError> {
    let file = crate::acquire::schedule_file::load(path).map_err(schedule_error)?;
    file.check_against_screen(path, station.screen.width, station.screen.height)
        .map_err(schedule_error)?;
    Ok(file.frames())
}

fn schedule_error(e: crate::acquire::schedule_file::ScheduleFileError) -> BudgetError {
    use crate::acquire::schedule_file::ScheduleFileError;
    match e {
        ScheduleFileError::Io { path, source } => BudgetError::Io { path, source },
        ScheduleFileError::Parse { path, source } => BudgetError::Parse {
            path,
            format: SCHEDULE_FORMAT,
            source,
        },
        ScheduleFileError::Invalid {
            path,
            field,
            problem,
        } => invalid(format!("{}: {field}", path.display()), problem),
    }
}

/// The spectral model's view of a schedule on `station`'s screen
/// ([`crate::solve::spectral::design`], the solver's own construction).
///
/// # Errors
/// [`BudgetError::Invalid`] when the directions are (nearly) parallel.
pub fn design(station: &Station, frames: &[FrameInfo]) -> Result<Design, BudgetError> {
    crate::solve::spectral::design(station, frames)
        .map_err(|e| invalid("the schedule", e.to_string()))
}

/// The camera's radiometry, as `mfd simulate` renders it (`sim::render`):
/// counts `gain · (ambient + Σ_k w_k (½ + ½ e(τ) cos …))`, the gain putting
/// the brightest pixel at 90 % of full scale, white read noise of
/// `noise_frac` of full scale.
#[derive(Debug, Clone, PartialEq)]
pub struct Radiometry {
    /// Read noise, fraction of full scale (`mfd simulate --noise`).
    pub noise_frac: f64,
    /// Bits per sample.
    pub bit_depth: u32,
    /// Ambient light, units of full-white screen radiance.
    pub ambient: f64,
    /// Modulation falloff τ_max.
    pub tau_max: f64,
}

impl Default for Radiometry {
    /// `mfd simulate`'s defaults, with the paper's 5 % noise (§5.1a).
    fn default() -> Self {
        Radiometry {
            noise_frac: 0.05,
            bit_depth: 16,
            ambient: 0.01,
            tau_max: 150.0,
        }
    }
}

impl Radiometry {
    /// The read noise, counts.
    pub fn sigma_counts(&self) -> f64 {
        self.noise_frac * f64::from((1u32 << self.bit_depth.min(16)) - 1)
    }

    /// Counts per unit radiance: 90 % of full scale on the brightest pixel.
    pub fn gain(&self, view: &TracedView) -> f64 {
        let brightest = view
            .pixels
            .iter()
            .map(|p| {
                self.ambient
                    + [p.front, p.back]
                        .iter()
                        .filter_map(|h| h.ok())
                        .map(|h| h.weight)
                        .sum::<f64>()
            })
            .fold(self.ambient, f64::max);
        0.9 * f64::from((1u32 << self.bit_depth.min(16)) - 1) / brightest
    }
}

/// Most pixels whose bound is evaluated exactly; beyond, one pixel per
/// `stride × stride` block stands for the block (see [`bound_map`]).
pub const MAX_BOUND_PIXELS: usize = 20_000;

/// Per pixel the Cramér–Rao covariance of `(u1, v1, u2, v2)`, px², in
/// `screen_cov.npy`'s layout (NaN where a reflection is absent).
///
/// With `stride > 1` the bound is evaluated at one pixel per `stride ×
/// stride` block and each reflection pattern (front only, back only,
/// both), and the block's other pixels of that pattern take it: the bound
/// varies with the front–back separation and the Fresnel weights, both
/// smooth over the element, while an exact map of a full sensor costs a
/// normal-equation sum over every frame at every pixel.
pub fn bound_map(
    design: &Design,
    view: &TracedView,
    gain: f64,
    radiometry: &Radiometry,
    stride: usize,
) -> Vec<f64> {
    let s = stride.max(1);
    let (w, h) = (view.width, view.height);
    let kappa = radiometry.tau_max.powi(-2);
    let sigma = radiometry.sigma_counts();
    // The information summed over the distinct frames with their counts:
    // the same sums (bit for bit without repeats) at a cost in distinct
    // frames, a few hundred of a planned 100 000.
    let repeats = Repeats::new(design);
    let pattern = |q: usize| {
        let p = &view.pixels[q];
        let has = |o: &crate::optics::trace::PathOutcome| o.is_ok_and(|h| h.weight > 0.0);
        usize::from(has(&p.front)) + 2 * usize::from(has(&p.back))
    };
    let blocks: Vec<(usize, usize)> = (0..h.div_ceil(s))
        .flat_map(|by| (0..w.div_ceil(s)).map(move |bx| (bx, by)))
        .collect();
    let per_block: Vec<Vec<(usize, [f64; 16])>> = blocks
        .par_iter()
        .map(|&(bx, by)| {
            let pixels: Vec<usize> = (by * s..((by + 1) * s).min(h))
                .flat_map(|j| (bx * s..((bx + 1) * s).min(w)).map(move |i| j * w + i))
                .collect();
            let mut cached: [Option<[f64; 16]>; 4] = [None; 4];
            let mut out = Vec::new();
            for q in pixels {
                let pat = pattern(q);
                if pat == 0 {
                    continue;
                }
                let cov = *cached[pat].get_or_insert_with(|| {
                    let one = TracedView {
                        width: 1,
                        height: 1,
                        pixels: vec![view.pixels[q]],
                    };
                    let c = truth_cov_map_repeated(
                        design,
                        &repeats,
                        &one,
                        gain,
                        radiometry.ambient,
                        kappa,
                        sigma,
                    );
                    std::array::from_fn(|k| c[k])
                });
                out.push((q, cov));
            }
            out
        })
        .collect();
    let mut map = vec![f64::NAN; 16 * view.pixels.len()];
    for (q, cov) in per_block.into_iter().flatten() {
        map[16 * q..16 * q + 16].copy_from_slice(&cov);
    }
    map
}

/// The block size that keeps the bound's evaluations near
/// [`MAX_BOUND_PIXELS`]: 1 on small cameras.
pub fn auto_stride(view: &TracedView) -> usize {
    let lit = view
        .pixels
        .iter()
        .filter(|p| p.front.is_ok() || p.back.is_ok())
        .count();
    let mut s = 1;
    while lit / (s * s) > MAX_BOUND_PIXELS {
        s += 1;
    }
    s
}

/// How the scene is made.
#[derive(Debug, Clone)]
pub struct SceneOptions {
    /// The camera's radiometry and noise.
    pub radiometry: Radiometry,
    /// Terms per surface, fixed.
    pub terms: usize,
    /// The element's rim beyond the aperture, mm.
    pub edge_margin_mm: f64,
    /// Block size of the bound's evaluation ([`bound_map`]); `None`: [`auto_stride`].
    pub bound_stride_px: Option<usize>,
}

impl Default for SceneOptions {
    fn default() -> Self {
        SceneOptions {
            radiometry: Radiometry::default(),
            terms: 36,
            edge_margin_mm: DEFAULT_EDGE_MARGIN_MM,
            bound_stride_px: None,
        }
    }
}

impl SceneOptions {
    /// The surface solver's options for the budget: the terms fixed, the
    /// bound's covariance used as it is (it is evaluated at the truth, so
    /// there is nothing to smooth).
    pub fn surface_options(&self) -> SurfaceOptions {
        SurfaceOptions {
            terms: Some(self.terms),
            covariance_smoothing_px: 0,
            ..SurfaceOptions::default()
        }
    }
}

/// The noise-free measurement of the expected surfaces on a station.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The expected surfaces (front, back).
    pub surfaces: (ZernikeSurface, ZernikeSurface),
    /// The traced paths.
    pub view: TracedView,
    /// The bound's covariance per pixel (`screen_cov.npy` layout), px².
    pub cov: Vec<f64>,
    /// The block size the bound was evaluated on.
    pub bound_stride_px: usize,
    /// The observations: the traced points with the bound's covariance.
    pub observations: Observations,
    /// Their reconstruction (χ² = 0): its covariance is the imaging noise's.
    pub solution: SurfaceSolution,
}

/// Traces `front` and `back` on `station`, evaluates the bound of the
/// schedule `frames` at every pixel and reconstructs the noise-free points.
///
/// # Errors
/// [`BudgetError`] for a schedule with parallel directions, or a failed
/// reconstruction (too few pixels for the terms, ill-conditioned).
pub fn scene(
    station: &Station,
    surfaces: (ZernikeSurface, ZernikeSurface),
    frames: &[FrameInfo],
    opts: &SceneOptions,
) -> Result<Scene, BudgetError> {
    let design = design(station, frames)?;
    let plate = Plate::new(
        station,
        surfaces.0.clone(),
        surfaces.1.clone(),
        opts.edge_margin_mm,
    );
    let view = TracedView::trace(station, &plate);
    let stride = opts.bound_stride_px.unwrap_or_else(|| auto_stride(&view));
    let gain = opts.radiometry.gain(&view);
    let cov = bound_map(&design, &view, gain, &opts.radiometry, stride);
    log::debug!("budget scene: bound on {stride}×{stride} px blocks, gain {gain:.4} counts per unit radiance");
    let observations =
        Observations::from_maps(station, &view.screen_coords(), Uncertainty::Cov(&cov))?;
    let solution = reconstruct(&observations, station, &opts.surface_options())?;
    Ok(Scene {
        surfaces,
        view,
        cov,
        bound_stride_px: stride,
        observations,
        solution,
    })
}

/// The expected surfaces: from an `mfd-surfaces/1` or `/2` file, or flat over the
/// station's aperture.
///
/// # Errors
/// [`BudgetError::Surfaces`] / [`BudgetError::Zernike`].
pub fn expected_surfaces(
    path: Option<&Path>,
    station: &Station,
) -> Result<(ZernikeSurface, ZernikeSurface), BudgetError> {
    use crate::formats::surfaces_file::{surfaces_or_flat, SurfacesOrFlatError};
    surfaces_or_flat(path, station).map_err(|e| match e {
        SurfacesOrFlatError::File(e) => BudgetError::from(e),
        SurfacesOrFlatError::Build { source, .. } | SurfacesOrFlatError::Flat(source) => {
            BudgetError::from(source)
        }
    })
}

/// The uncertainty of the file (if any) with per-degree-of-freedom 1σ
/// values from the command line (`("camera.z_mm", 0.5)`, flag `--std`)
/// added or replacing the file's: a replaced one loses its correlations.
///
/// # Errors
/// [`BudgetError::Invalid`] naming the flag for an unknown name or a σ ≤ 0,
/// and when there is no σ at all.
pub fn merge_std(
    file: Option<StationUncertainty>,
    stds: &[(String, f64)],
    station_name: &str,
) -> Result<StationUncertainty, BudgetError> {
    let mut names: Vec<Dof> = Vec::new();
    let mut cov_entries: Vec<(usize, usize, f64)> = Vec::new();
    let mut station = station_name.to_string();
    if let Some(u) = &file {
        station = u.station.clone();
        names = u.names.clone();
        for r in 0..names.len() {
            for c in 0..names.len() {
                cov_entries.push((r, c, u.covariance[(r, c)]));
            }
        }
    }
    for (name, s) in stds {
        let flag = format!("--std {name}={s}");
        let dof = Dof::parse(name).ok_or_else(|| {
            invalid(&flag, format!("`{name}` is not a degree of freedom of the spec's table (e.g. camera.z_mm, screen.rz_deg, element.thickness_mm)"))
        })?;
        if !(s.is_finite() && *s > 0.0) {
            return Err(invalid(
                &flag,
                format!("expected a 1σ > 0 in the unit of `{name}`, found {s}"),
            ));
        }
        let k = names.iter().position(|&d| d == dof).unwrap_or_else(|| {
            names.push(dof);
            names.len() - 1
        });
        cov_entries.retain(|&(r, c, _)| r != k && c != k);
        cov_entries.push((k, k, s * s));
    }
    if names.is_empty() {
        return Err(invalid(
            "--uncertainty / --std",
            "no degree of freedom has a 1σ: give an uncertainty file or --std NAME=SIGMA",
        ));
    }
    let mut covariance = DMatrix::zeros(names.len(), names.len());
    for (r, c, v) in cov_entries {
        covariance[(r, c)] = v;
    }
    Ok(StationUncertainty {
        station,
        correlated: names.len(),
        names,
        covariance,
    })
}

/// Checks that an uncertainty file is the one of `station_path`: its
/// `station` field, relative to the uncertainty file, names the same file.
///
/// # Errors
/// [`BudgetError::Invalid`] naming both files.
pub fn check_station(
    uncertainty_path: &Path,
    named: &str,
    station_path: &Path,
) -> Result<(), BudgetError> {
    let dir = uncertainty_path.parent().unwrap_or(Path::new("."));
    let target = dir.join(named);
    let same = match (target.canonicalize(), station_path.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        return Ok(());
    }
    Err(invalid(
        format!("{}: station", uncertainty_path.display()),
        format!(
            "these are the uncertainties of `{}`, not of the station given ({}); use that station's uncertainty file",
            target.display(),
            station_path.display()
        ),
    ))
}
