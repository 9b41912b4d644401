//! Screen points as the surface stage's input: the points of every camera
//! pixel read from `screen_coords.npy`, with their uncertainty (a
//! covariance, standard deviations, or none known).

use std::path::{Path, PathBuf};

use super::PipelineError;
use crate::formats::npy;
use crate::optics::station::Station;
use crate::solve::surfaces::Uncertainty;

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
    pub(super) fn uncertainty(&self) -> Uncertainty<'_> {
        match &self.uncertainty {
            PointUncertainty::Covariance(c) => Uncertainty::Cov(c),
            PointUncertainty::Std(s) => Uncertainty::Std(s),
            PointUncertainty::Unknown => Uncertainty::Unknown,
        }
    }
}
