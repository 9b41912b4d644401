//! The files of a result folder: what [`Reconstruction::write`] puts in it
//! (the spectral maps, `surfaces.json`, the height maps, the pictures and
//! `summary.json`), and `surfaces.json`'s content from a surface stage.

use std::path::{Path, PathBuf};

use super::{result_dir, DirectReport, PipelineError, Reconstruction, SurfaceStage, HEIGHT_GRID};
use crate::budget::refine::Refined;
use crate::formats::npy;
use crate::formats::surfaces_file::{SurfaceCoefficients, SurfaceEntry, SurfacesFile, ZernikeSpec};
use crate::optics::outline::Outline;
use crate::optics::zernike::ZernikeSurface;
use crate::report::pictures;
use crate::report::summary::Summary;
use crate::solve::surfaces::report::{height_grid, SurfaceFigures};

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
        written.extend(write_refined(out, r)?);
    }
    if let Some(d) = &stage.direct {
        written.extend(write_direct(out, d)?);
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
        written.extend(write_surface(
            out,
            name,
            surface,
            &sol.outline,
            figures,
            summary,
        )?);
    }
    written.extend(pictures::breakdown(out, summary)?);
    let path = out.join("summary.json");
    write_json(&path, summary)?;
    written.push(path);
    Ok(written)
}

/// The refined station and its uncertainty, for the next measurement.
fn write_refined(out: &Path, r: &Refined) -> Result<Vec<PathBuf>, PipelineError> {
    let mut written = Vec::new();
    let path = out.join("station_refined.toml");
    r.station.save(&path)?;
    written.push(path);
    let path = out.join("station_refined_uncertainty.toml");
    let mut unc = r.uncertainty.clone();
    unc.station = "station_refined.toml".into();
    unc.save(&path)?;
    written.push(path);
    Ok(written)
}

/// The surface-domain fit's per-pixel maps: the points its surfaces
/// predict, and each pixel's pull against them (a defect the Zernike model
/// cannot follow shows there).
fn write_direct(out: &Path, d: &DirectReport) -> Result<Vec<PathBuf>, PipelineError> {
    let mut written = Vec::new();
    let (w, h) = (d.width, d.chi2_map.len() / d.width.max(1));
    let path = out.join("direct_screen_coords.npy");
    npy::write_f64(&path, &[h, w, 2, 2], &d.predicted)?;
    written.push(path);
    let path = out.join("direct_chi2.npy");
    npy::write_f64(&path, &[h, w], &d.chi2_map)?;
    written.push(path);
    Ok(written)
}

/// One surface's height map (`{name}_height_nm.npy`) and its pictures: the
/// map, and the coefficients with the total σ where the summary has the
/// station's part.
fn write_surface(
    out: &Path,
    name: &str,
    surface: &ZernikeSurface,
    outline: &Outline,
    figures: &SurfaceFigures,
    summary: &Summary,
) -> Result<Vec<PathBuf>, PipelineError> {
    let mut written = Vec::new();
    let grid = height_grid(surface, outline, HEIGHT_GRID);
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
    let entry = |surface: &ZernikeSurface, back: bool| {
        let (std, expected) = summary
            .reported(back)
            .map_or((None, None), |(s, e)| (Some(s.to_vec()), Some(e)));
        let figures = if back {
            summary.back.as_ref()
        } else {
            Some(&summary.front)
        };
        SurfaceEntry::Reconstructed(SurfaceCoefficients {
            coefficients_nm: surface.coefficients_nm().to_vec(),
            std_nm: std,
            expected_error_rms_nm: expected,
            // The orthonormal σ are the noise's: not written beside a station part.
            orthonormal_std_nm: figures
                .filter(|_| summary.station.is_none())
                .and_then(|f| f.orthonormal_std_nm.clone()),
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
    SurfacesFile::with_outline(
        ZernikeSpec::of(sol.front.basis()),
        &sol.outline.shape,
        front,
        back,
    )
}
