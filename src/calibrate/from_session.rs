//! From a session folder to a calibration: the session loaded and checked
//! ([`Session::load`]), the target centroids found in their frames, the
//! reference flat's acquisition decoded into screen points by the spectral
//! stage (one reflection), and the numbers handed to [`calibrate`].

use std::path::{Path, PathBuf};

use nalgebra::{Matrix2, Point2, Vector3};

use super::calibration::{calibrate, Calibration};
use super::centroid::CentroidError;
use super::error::CalibrationError;
use super::input::{CalibrationInput, FlatPixel, MarkedPixel, Target};
use super::session::{Session, SessionError};
use crate::acquire::acquisition::{Acquisition, AcquisitionError};
use crate::optics::station::Station;
use crate::solve::spectral::{FeedError, SpectralConfig, SpectralError, SpectralSolver};

/// The σ taken for a centroid given as `image_px`, px per axis: the
/// session format states none, and a centroid a lab's own tool found on a
/// clean spot is good to about this (the centroids mfd finds in frames are
/// 0.05–0.1 px); the report's target χ²/dof says whether it was right.
pub const GIVEN_CENTROID_STD_PX: f64 = 0.1;

/// Above this share of the decoded flat pixels showing two reflections, the
/// acquisition is not of a flat (a plate, or the element left in place).
/// A mirror shows none; a few percent come from the fit's own false
/// positives near the flat's rim.
pub const TWO_REFLECTION_SHARE: f64 = 0.05;

/// The most flat pixels handed to the adjustment: every one carries
/// independent information, but the screen's six degrees of freedom are
/// determined long before; beyond this the pixels are taken on a regular
/// grid over the sensor (every s-th pixel of every s-th row).
pub const MAX_FLAT_PIXELS: usize = 20_000;

/// Why a session could not be turned into a calibration.
#[derive(Debug, thiserror::Error)]
pub enum SessionSolveError {
    /// The session itself.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// A target frame.
    #[error(transparent)]
    Centroid(#[from] CentroidError),
    /// The reference flat's acquisition could not be read.
    #[error("reference_flat.acquisition: {source}")]
    FlatAcquisition {
        /// The acquisition's error (names the file or frame).
        #[source]
        source: AcquisitionError,
    },
    /// The spectral stage could not decode the reference flat.
    #[error("reference_flat.acquisition ({path}): {source}")]
    FlatDecode {
        /// The acquisition.
        path: PathBuf,
        /// The stage's error.
        #[source]
        source: SpectralError,
    },
    /// The reference flat's acquisition is not of a flat.
    #[error(
        "reference_flat.acquisition ({path}): {two} of {decoded} decoded pixels show two \
         reflections: record the reference flat (one reflecting surface) standing where the \
         element will stand, not the element itself"
    )]
    TwoReflections {
        /// The acquisition.
        path: PathBuf,
        /// Pixels with two reflections.
        two: usize,
        /// Pixels decoded.
        decoded: usize,
    },
    /// Too few flat pixels decoded.
    #[error(
        "reference_flat.acquisition ({path}): only {decoded} pixels decoded: check that the \
         flat fills the camera's view and the fringes are in focus"
    )]
    FlatTooSmall {
        /// The acquisition.
        path: PathBuf,
        /// Pixels decoded.
        decoded: usize,
    },
    /// The adjustment.
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
}

impl crate::outcome::Classify for SessionSolveError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            SessionSolveError::Session(e) => e.outcome(),
            SessionSolveError::Centroid(e) => e.outcome(),
            SessionSolveError::Calibration(e) => e.outcome(),
            SessionSolveError::FlatAcquisition { source } => source.outcome(),
            SessionSolveError::FlatDecode { source, .. } => source.outcome(),
            // The reference flat's recording is of something else.
            SessionSolveError::TwoReflections { .. } => Some(Outcome::Input),
            // Too little of the flat decoded: nothing to measure there.
            SessionSolveError::FlatTooSmall { .. } => Some(Outcome::NoSignal),
        }
    }
}

/// What the reference flat's decode gave.
#[derive(Debug, Clone, PartialEq)]
pub struct FlatDecode {
    /// The acquisition.
    pub path: PathBuf,
    /// Frames read.
    pub frames: usize,
    /// Camera pixels with a decoded screen point.
    pub decoded: usize,
    /// Of them, with two reflections.
    pub two_reflections: usize,
    /// Handed to the adjustment.
    pub used: usize,
}

/// A solved session.
#[derive(Debug, Clone)]
pub struct SolvedSession {
    /// The calibration.
    pub calibration: Calibration,
    /// The flat's decode.
    pub flat: FlatDecode,
    /// Targets whose centroid was given (`image_px`, σ assumed
    /// [`GIVEN_CENTROID_STD_PX`]).
    pub given_centroids: usize,
    /// The numbers the calibration was computed from (for its pictures).
    pub input: CalibrationInput,
}

/// The nominal station to decode the flat on: the flat stands on the
/// reference plane and fills more of the view than the element, so the
/// element's aperture is widened to the camera's footprint on `z = 0`.
fn flat_station(nominal: &Station) -> Station {
    let mut s = nominal.clone();
    s.element.pose = Default::default();
    let cam = &s.camera;
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let mut reach: f64 = s.element.aperture_radius_mm;
    for (x, y) in [
        (0.0, 0.0),
        (w, 0.0),
        (0.0, h),
        (w, h),
        (w / 2.0, 0.0),
        (0.0, h / 2.0),
    ] {
        let d = cam.ray_through(x, y);
        if d.z < 0.0 {
            let p = cam.position_mm + (-cam.position_mm.z / d.z) * d.as_ref();
            let c = s.element.aperture_center_mm;
            reach = reach.max((p.x - c.x).hypot(p.y - c.y));
        }
    }
    s.element.aperture_radius_mm = reach;
    s
}

/// Decodes the reference flat's acquisition into flat pixels.
///
/// # Errors
/// [`SessionSolveError`] naming `reference_flat.acquisition`.
pub fn decode_flat(
    session: &Session,
    config: &SpectralConfig,
) -> Result<(Vec<FlatPixel>, FlatDecode), SessionSolveError> {
    let path = session.reference_flat.clone();
    let flat_err = |source| SessionSolveError::FlatAcquisition { source };
    let mut acq = Acquisition::open(&path).map_err(flat_err)?;
    let station = flat_station(&session.starting_station());
    let cam = &station.camera;
    acq.check_resolution(cam.width, cam.height)
        .map_err(flat_err)?;
    let decode = |source| SessionSolveError::FlatDecode {
        path: path.clone(),
        source,
    };
    let mut solver = SpectralSolver::new(&station, acq.frames(), config.clone()).map_err(decode)?;
    let frames = acq.frames().len();
    solver
        .push_acquisition(&acq, frames, &mut |_, _| {})
        .map_err(|e| match e {
            FeedError::Read(e) => flat_err(e),
            FeedError::Push(e) => decode(e),
        })?;
    let maps = solver.solve().map_err(decode)?;
    let (coords, cov) = (maps.screen_coords(), maps.screen_cov());
    let w = cam.width as usize;
    let mut pixels = Vec::new();
    let mut two = 0;
    for k in 0..cam.pixel_count() {
        let s = &coords[4 * k..4 * k + 4];
        if !(s[0].is_finite() && s[1].is_finite()) {
            continue;
        }
        if s[2].is_finite() && s[3].is_finite() {
            two += 1;
            continue;
        }
        let c = &cov[16 * k..16 * k + 16];
        pixels.push(FlatPixel {
            pixel: [(k % w) as u32, (k / w) as u32],
            screen_px: Point2::new(s[0], s[1]),
            screen_cov_px2: Matrix2::new(c[0], c[1], c[4], c[5]),
        });
    }
    let decoded = pixels.len() + two;
    if decoded > 0 && two as f64 > TWO_REFLECTION_SHARE * decoded as f64 {
        return Err(SessionSolveError::TwoReflections { path, two, decoded });
    }
    if pixels.len() < 100 {
        return Err(SessionSolveError::FlatTooSmall { path, decoded });
    }
    // Every s-th pixel of every s-th row: a regular grid over the flat.
    let s = (pixels.len() as f64 / MAX_FLAT_PIXELS as f64)
        .sqrt()
        .ceil()
        .max(1.0) as u32;
    let used: Vec<FlatPixel> = pixels
        .into_iter()
        .filter(|p| p.pixel[0] % s == 0 && p.pixel[1] % s == 0)
        .collect();
    let info = FlatDecode {
        path,
        frames,
        decoded,
        two_reflections: two,
        used: used.len(),
    };
    Ok((used, info))
}

/// Loads, decodes and calibrates the session at `path` (its folder or
/// `session.toml`).
///
/// # Errors
/// [`SessionSolveError`] naming the entry, file or step at fault.
pub fn solve_session(
    path: &Path,
    config: &SpectralConfig,
) -> Result<SolvedSession, SessionSolveError> {
    let session = Session::load(path)?;
    let observed = session.centroids()?;
    let mut given = 0;
    let given_cov = Matrix2::identity() * GIVEN_CENTROID_STD_PX.powi(2);
    let targets = observed
        .iter()
        .map(|t| Target {
            stage_mm: t.stage_mm.coords,
            pixel: t.position_px,
            pixel_cov_px2: t.covariance_px2.unwrap_or_else(|| {
                given += 1;
                given_cov
            }),
        })
        .collect();
    let (flat_screen, flat) = decode_flat(&session, config)?;
    let v = |p: &nalgebra::Point3<f64>| -> Vector3<f64> { p.coords };
    let e = &session.element;
    let mut input = CalibrationInput {
        nominal: session.nominal.clone(),
        stage_std_mm: session.stage_std_mm,
        element_center_stage_mm: e.center_stage_mm,
        thickness_mm: (e.thickness_mm, e.thickness_std_mm),
        refractive_index: (e.refractive_index, e.refractive_index_std),
        flat_points_stage_mm: session.flat_points_mm.iter().map(v).collect(),
        element_points_stage_mm: session.element_points_mm.iter().map(v).collect(),
        targets,
        flat_screen,
        screen_points: session
            .screen_points
            .iter()
            .map(|m| MarkedPixel {
                stage_mm: m.stage_mm.coords,
                screen_px: m.screen_px,
            })
            .collect(),
    };
    let mut calibration = calibrate(&input)?;
    // The centroids' σ count the background's noise only (the session gives
    // no camera gain for the spot's own shot noise; `centroid.rs`), so they
    // are a lower bound. Where the resection's χ²/dof says so beyond its
    // own scatter (3 σ of χ²/dof, √(2/dof)), the targets' covariances are
    // scaled by it (the Birge ratio) and the session adjusted again.
    let resection = calibration
        .report
        .steps
        .first()
        .map(|s| (s.chi2_per_dof, s.dof));
    if let Some((ratio, dof)) =
        resection.filter(|&(r, d)| d > 0 && r > 1.0 + 3.0 * (2.0 / d as f64).sqrt())
    {
        log::info!("target centroids: σ scaled by √{ratio:.2} (resection χ²/dof over {dof} dof)");
        let mut scaled = input.clone();
        for t in &mut scaled.targets {
            t.pixel_cov_px2 *= ratio;
        }
        calibration = calibrate(&scaled)?;
        input = scaled;
        calibration.report.notes.push(format!(
            "the target centroids' σ were scaled by √{ratio:.2} = {:.2}: the first resection's \
             χ²/dof over {dof} degrees of freedom (a centroid's σ from the frame's background \
             leaves out the spot's own shot noise)",
            ratio.sqrt()
        ));
    }
    Ok(SolvedSession {
        calibration,
        flat,
        given_centroids: given,
        input,
    })
}
