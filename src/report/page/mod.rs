//! The measurement report (`mfd report`): one self-contained HTML page of a
//! result folder that an operator can file — what was measured, both
//! surfaces with their coefficient charts, the uncertainty and its budget,
//! the fit, the spectral stage's quality maps, the calibration used, the
//! warnings, and (when given) the comparison with an interferometer.
//!
//! It reads what `pipeline::Reconstruction::write` put in the folder
//! (`summary.json`, `surfaces.json`, the pictures, the spectral arrays) and
//! draws what is not there as a picture (the quality maps) with
//! [`crate::plot`].

mod context;
pub mod html;
mod quality;
pub mod result_block;
mod sections;

use std::path::{Path, PathBuf};

use crate::compare::Comparison;

pub use context::Context;
pub use html::Page;

/// What went wrong making a report; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A JSON file is not what it should be.
    #[error("{path}: not a valid file of its kind: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// An array has the wrong shape.
    #[error("{path}: shape {found:?}, expected {expected}")]
    Shape {
        /// The file.
        path: PathBuf,
        /// The shape the report reads.
        expected: &'static str,
        /// The file's shape.
        found: Vec<usize>,
    },
    /// The folder holds neither `surfaces.json` nor `screen_coords.npy`.
    #[error(
        "{dir}: no reconstruction here (neither surfaces.json nor screen_coords.npy); give the \
         folder `mfd reconstruct --out` or `mfd measure --out …/result` wrote"
    )]
    NoResult {
        /// The folder.
        dir: PathBuf,
    },
    /// A file or folder the report needs is not there.
    #[error("{path}: not there: {why}")]
    Missing {
        /// The file or folder.
        path: PathBuf,
        /// Why the report needs it and what to do.
        why: String,
    },
    /// An array could not be read.
    #[error(transparent)]
    Npy(#[from] crate::formats::npy::NpyError),
    /// `surfaces.json` could not be read.
    #[error(transparent)]
    Surfaces(#[from] crate::formats::surfaces_file::SurfacesFileError),
    /// A picture could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// The acquisition could not be opened.
    #[error(transparent)]
    Acquisition(#[from] crate::acquire::acquisition::AcquisitionError),
    /// The station could not be read.
    #[error(transparent)]
    Station(#[from] crate::optics::station::StationError),
    /// The comparison's pictures could not be drawn.
    #[error(transparent)]
    Compare(#[from] crate::compare::CompareError),
}

impl crate::outcome::Classify for ReportError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            ReportError::Io { source, .. } => crate::outcome::io_outcome(source),
            // A result file that is not what its name says, or no result.
            ReportError::Json { .. }
            | ReportError::Shape { .. }
            | ReportError::NoResult { .. }
            | ReportError::Missing { .. } => Some(Outcome::Input),
            ReportError::Npy(e) => e.outcome(),
            ReportError::Surfaces(e) => e.outcome(),
            ReportError::Acquisition(e) => e.outcome(),
            ReportError::Station(e) => e.outcome(),
            ReportError::Compare(e) => e.outcome(),
            // Drawing a picture: a failure of its own (exit 1).
            ReportError::Plot(_) => None,
        }
    }
}

/// What to put beside the result folder's own content.
#[derive(Default)]
pub struct ReportOptions<'a> {
    /// The acquisition folder (default: `RESULT/../acquisition` when it
    /// exists, as `mfd measure` lays it out).
    pub acquisition: Option<PathBuf>,
    /// The calibration's folder (`report.json`, `targets.png`, …; default:
    /// the folder of the station file the acquisition names).
    pub calibration: Option<PathBuf>,
    /// A comparison with an interferometer to include.
    pub comparison: Option<&'a Comparison>,
}

/// The report of `result` as an HTML document.
///
/// # Errors
/// [`ReportError`] naming the file that could not be read or drawn.
pub fn build(result: &Path, options: &ReportOptions) -> Result<String, ReportError> {
    let surfaces = result.join("surfaces.json");
    if !surfaces.is_file() && !result.join("screen_coords.npy").is_file() {
        return Err(ReportError::NoResult {
            dir: result.to_path_buf(),
        });
    }
    check_inputs(result, options)?;
    let context = Context::find(result, options.acquisition.as_deref())?;
    let summary = sections::load_summary(result)?;
    let written = ["summary.json", "surfaces.json", "screen_coords.npy"]
        .iter()
        .find_map(|f| modified_s(&result.join(f)));
    let mut page = Page::new("Measurement report");
    let scratch = Scratch::new()?;
    if let Some(s) = &summary {
        result_block::result_block(&mut page, result, s, &scratch.0)?;
    }
    context.section(&mut page, result, written);
    let flags = quality::flag_counts(result)?;
    sections::warnings(&mut page, summary.as_ref(), flags.as_ref());
    if let Some(s) = &summary {
        sections::surfaces(&mut page, result, s)?;
        sections::uncertainty(&mut page, result, s)?;
        sections::fit(&mut page, s);
    } else if surfaces.is_file() {
        page.heading("Surfaces");
        page.paragraph("surfaces.json is here but no summary.json: the figures are not known.");
    }
    if let Some(c) = options.comparison {
        sections::comparison(&mut page, c)?;
    }
    sections::spectral(
        &mut page,
        flags.as_ref(),
        quality::maps(result, &scratch.0)?,
    );
    context.calibration(&mut page, options.calibration.as_deref())?;
    Ok(page.finish())
}

/// Refuses what the page would otherwise present as fine: a calibration
/// folder given that is not one (the page would say "no calibration
/// report" as if none had been asked for), and a result whose
/// `surfaces.json`, the result itself, is not valid, or missing where
/// `summary.json` describes its surfaces (the page's figures would be of
/// a result that is not there).
fn check_inputs(result: &Path, options: &ReportOptions) -> Result<(), ReportError> {
    if let Some(dir) = &options.calibration {
        if !dir.join("report.json").is_file() {
            return Err(ReportError::Missing {
                path: dir.join("report.json"),
                why: "--calibration names the folder `mfd calibrate solve --out` wrote (its \
                      report.json, targets.png, flat_residuals.png); give that folder, or leave \
                      --calibration out"
                    .into(),
            });
        }
    }
    let surfaces = result.join("surfaces.json");
    if surfaces.is_file() {
        crate::formats::surfaces_file::SurfacesFile::load(&surfaces)?;
    } else if result.join("summary.json").is_file() {
        return Err(ReportError::Missing {
            path: surfaces,
            why: "summary.json describes the surfaces this file holds: the result folder is \
                  incomplete; reconstruct again into a new --out folder"
                .into(),
        });
    }
    Ok(())
}

/// Writes the report of `result` to `out` (default `RESULT/report.html`);
/// returns the file written.
///
/// # Errors
/// As [`build`]; [`ReportError::Io`] when the file cannot be written.
pub fn write(
    result: &Path,
    out: Option<&Path>,
    options: &ReportOptions,
) -> Result<PathBuf, ReportError> {
    let html = build(result, options)?;
    let path = out.map_or_else(|| result.join("report.html"), Path::to_path_buf);
    std::fs::write(&path, html).map_err(|source| ReportError::Io {
        path: path.clone(),
        source,
    })?;
    Ok(path)
}

/// The file's modification time, seconds since the Unix epoch.
fn modified_s(path: &Path) -> Option<u64> {
    let t = std::fs::metadata(path).ok()?.modified().ok()?;
    Some(t.duration_since(std::time::UNIX_EPOCH).ok()?.as_secs())
}

/// A folder of its own under the system's temporary folder for pictures
/// drawn on the way (the plotting writers draw into files), removed when
/// dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new() -> Result<Scratch, ReportError> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static COUNT: AtomicUsize = AtomicUsize::new(0);
        let n = COUNT.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("mfd-report-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|source| ReportError::Io {
            path: dir.clone(),
            source,
        })?;
        Ok(Scratch(dir))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Err(e) = std::fs::remove_dir_all(&self.0) {
            log::warn!(
                "{}: could not remove the report's scratch folder: {e}",
                self.0.display()
            );
        }
    }
}
