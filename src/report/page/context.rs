//! What was measured, for the report's first section: the acquisition
//! (frames, schedule), the station and element it names, when the result
//! was written, and the calibration that made the station (its
//! `report.json` and pictures, found beside the station file).

use std::path::{Path, PathBuf};

use super::html::{utc_date, Page};
use super::ReportError;
use crate::acquire::acquisition::Acquisition;
use crate::optics::station::Station;

/// The acquisition and station of a result, where they can be found.
pub struct Context {
    /// The acquisition folder, when known.
    pub acquisition: Option<Acquisition>,
    /// The station file and the station, when known.
    pub station: Option<(PathBuf, Station)>,
}

impl Context {
    /// The acquisition at `acquisition` (default: `RESULT/../acquisition`,
    /// where `mfd measure` puts it, when that exists) and the station it
    /// names.
    ///
    /// # Errors
    /// [`ReportError`] when a named acquisition or its station cannot be read.
    pub fn find(result: &Path, acquisition: Option<&Path>) -> Result<Context, ReportError> {
        let beside = result.parent().map(|p| p.join("acquisition"));
        let dir = match acquisition {
            Some(a) => Some(a.to_path_buf()),
            None => beside.filter(|d| d.join("acquisition.toml").is_file()),
        };
        let Some(dir) = dir else {
            return Ok(Context {
                acquisition: None,
                station: None,
            });
        };
        let acq = Acquisition::open(&dir)?;
        let path = acq.station_path().to_path_buf();
        let station = Station::load(&path)?;
        Ok(Context {
            acquisition: Some(acq),
            station: Some((path, station)),
        })
    }

    /// The "what was measured" section.
    pub fn section(&self, page: &mut Page, result: &Path, written: Option<u64>) {
        page.heading("What was measured");
        let mut rows = vec![vec!["result folder".into(), result.display().to_string()]];
        if let Some(t) = written {
            rows.push(vec!["result written".into(), utc_date(t)]);
        }
        match &self.acquisition {
            Some(a) => rows.extend(acquisition_rows(a)),
            None => rows.push(vec![
                "acquisition".into(),
                "not found (give --acquisition)".into(),
            ]),
        }
        if let Some((path, s)) = &self.station {
            let e = &s.element;
            rows.push(vec!["station".into(), path.display().to_string()]);
            rows.push(vec![
                "element".into(),
                format!(
                    "n = {}, thickness {} mm, aperture radius {} mm at ({}, {}) mm",
                    e.refractive_index,
                    e.thickness_mm,
                    e.aperture_radius_mm,
                    e.aperture_center_mm.x,
                    e.aperture_center_mm.y
                ),
            ]);
            rows.push(vec![
                "camera".into(),
                format!(
                    "{} × {} px, f = {} mm{}",
                    s.camera.width,
                    s.camera.height,
                    s.camera.focal_length_mm,
                    s.camera
                        .aspect_ratio
                        .map_or(String::new(), |a| format!(", fy/fx = {a}"))
                ),
            ]);
        }
        page.pairs(&rows);
    }

    /// The "calibration" section: the station file, whether an uncertainty
    /// sits beside it, and the calibration's steps and residuals from
    /// `report.json` with its pictures, when the station came from
    /// `mfd calibrate solve`;
    ///
    /// # Errors
    /// [`ReportError`] when a calibration file exists but cannot be read.
    /// `folder` (the calibration's output folder, e.g. where `mfd measure`'s
    /// `--station` came from; `mfd measure` copies the station into the
    /// acquisition) is searched instead of the station file's folder.
    pub fn calibration(&self, page: &mut Page, folder: Option<&Path>) -> Result<(), ReportError> {
        page.heading("Calibration");
        let Some((path, _)) = &self.station else {
            page.paragraph("The station is not known (no acquisition found).");
            return Ok(());
        };
        let dir = folder.unwrap_or_else(|| path.parent().unwrap_or(Path::new(".")));
        let unc = dir.join("station_uncertainty.toml");
        page.paragraph(&format!(
            "Station {}; {}",
            path.display(),
            if unc.is_file() {
                format!("its uncertainty {}", unc.display())
            } else {
                "no station_uncertainty.toml beside it".to_string()
            }
        ));
        let report = dir.join("report.json");
        if !report.is_file() {
            page.note("No calibration report (report.json) beside the station file.");
            return Ok(());
        }
        let text = std::fs::read_to_string(&report).map_err(|source| ReportError::Io {
            path: report.clone(),
            source,
        })?;
        let json: serde_json::Value =
            serde_json::from_str(&text).map_err(|source| ReportError::Json {
                path: report.clone(),
                source,
            })?;
        page.table(
            &[
                "step / block",
                "χ²/dof",
                "count",
                "RMS",
                "expected RMS",
                "unit",
            ],
            &calibration_rows(&json),
        );
        for note in json["notes"].as_array().into_iter().flatten() {
            page.note(note.as_str().unwrap_or_default());
        }
        for (file, caption) in [
            ("targets.png", "calibration targets and their residuals"),
            ("flat_residuals.png", "flat's residuals"),
        ] {
            let p = dir.join(file);
            if p.is_file() {
                let png = std::fs::read(&p).map_err(|source| ReportError::Io {
                    path: p.clone(),
                    source,
                })?;
                page.png(&png, caption);
            }
        }
        Ok(())
    }
}

/// Frames and schedule of an acquisition.
fn acquisition_rows(a: &Acquisition) -> Vec<Vec<String>> {
    let frames = a.frames();
    let mut dirs: Vec<f64> = frames.iter().map(|f| f.direction_deg).collect();
    dirs.sort_by(f64::total_cmp);
    dirs.dedup();
    let mut phases: Vec<f64> = frames.iter().map(|f| f.phase_rad).collect();
    phases.sort_by(f64::total_cmp);
    phases.dedup();
    let (lo, hi) = frames
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), f| {
            (l.min(f.tau), h.max(f.tau))
        });
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    vec![
        vec![
            "acquisition".into(),
            a.manifest_path().display().to_string(),
        ],
        vec![
            "frames".into(),
            format!("{} ({} complete)", frames.len(), a.complete_frames()),
        ],
        vec![
            "schedule".into(),
            format!(
                "directions {} °; τ {lo} … {hi}; phases {} rad",
                list(&dirs),
                list(&phases)
            ),
        ],
    ]
}

/// One row per calibration step, then one per residual block.
fn calibration_rows(json: &serde_json::Value) -> Vec<Vec<String>> {
    let num = |v: &serde_json::Value| v.as_f64().map_or("–".into(), |x| format!("{x:.4}"));
    let mut rows = Vec::new();
    for step in json["steps"].as_array().into_iter().flatten() {
        rows.push(vec![
            step["name"].as_str().unwrap_or("?").to_string(),
            num(&step["chi2_per_dof"]),
            String::new(),
            String::new(),
            String::new(),
            String::new(),
        ]);
        for b in step["blocks"].as_array().into_iter().flatten() {
            rows.push(vec![
                format!("  {}", b["name"].as_str().unwrap_or("?")),
                String::new(),
                b["count"].as_u64().map_or("–".into(), |c| c.to_string()),
                num(&b["rms"]),
                num(&b["expected_rms"]),
                b["unit"].as_str().unwrap_or("").to_string(),
            ]);
        }
    }
    rows
}
