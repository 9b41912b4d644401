//! The report's sections from a result folder's `summary.json` and
//! pictures: warnings, surfaces, uncertainty, fit, spectral quality, and
//! the comparison with an interferometer.

use std::path::Path;

use super::quality::{FlagCounts, Picture};
use super::{Page, ReportError};
use crate::compare::Comparison;
use crate::report::summary::{StageDetail, Summary};

/// `summary.json` of `dir`, when there is one.
///
/// # Errors
/// [`ReportError`] when it exists but cannot be read.
pub fn load_summary(dir: &Path) -> Result<Option<Summary>, ReportError> {
    let path = dir.join("summary.json");
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|source| ReportError::Io {
        path: path.clone(),
        source,
    })?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|source| ReportError::Json { path, source })
}

/// How many standard deviations of χ²/dof (√(2/dof) for a χ² of `dof`
/// degrees of freedom) away from 1 the report calls "far": beyond 5 the
/// model with the stated σ would give such a value with probability below
/// 1e-6, so either the σ or the model are off.
pub const CHI2_FAR_SIGMAS: f64 = 5.0;

/// Whether a reduced χ² is far from 1 for `dof` degrees of freedom.
pub fn chi2_far(reduced: f64, dof: usize) -> bool {
    let dof = dof.max(1) as f64;
    !reduced.is_finite() || (reduced - 1.0).abs() > CHI2_FAR_SIGMAS * (2.0 / dof).sqrt()
}

fn read(path: &Path) -> Result<Option<Vec<u8>>, ReportError> {
    if !path.is_file() {
        return Ok(None);
    }
    std::fs::read(path)
        .map(Some)
        .map_err(|source| ReportError::Io {
            path: path.to_path_buf(),
            source,
        })
}

/// The warnings: saturation, flagged pixels, outliers, a reduced χ² far
/// from 1, a missing back, a geometry taken as exact.
pub fn warnings(page: &mut Page, summary: Option<&Summary>, flags: Option<&FlagCounts>) {
    page.heading("Warnings");
    let mut any = false;
    let mut warn = |page: &mut Page, text: String| {
        any = true;
        page.warning(&text);
    };
    if let Some((with_data, counts)) = flags {
        for (name, n) in counts {
            let worth = matches!(
                *name,
                "saturated samples excluded"
                    | "reflections not separable"
                    | "offset disagrees with the geometry"
                    | "not converged"
                    | "negative amplitude"
            );
            if worth && *n > 0 {
                warn(
                    page,
                    format!("{n} of {with_data} pixels flagged: {name} (flags.npy)"),
                );
            }
        }
    }
    if let Some(s) = summary {
        if s.outliers.count > 0 {
            warn(
                page,
                format!(
                    "{} pixels left out of the surface fit as outliers ({})",
                    s.outliers.count, s.outliers.rule
                ),
            );
        }
        let params = s.front.terms + s.back.as_ref().map_or(0, |b| b.terms) + s.refined.len();
        let dof = s.residuals.saturating_sub(params);
        if chi2_far(s.reduced_chi2, dof) {
            warn(
                page,
                format!(
                    "reduced χ² of the surface fit {:.3} is far from 1 (more than {CHI2_FAR_SIGMAS} \
                     × √(2/{dof}) away): the screen points' σ or the model do not hold; the \
                     covariance was scaled by {:.3}",
                    s.reduced_chi2, s.covariance_scale
                ),
            );
        }
        if s.back.is_none() {
            warn(page, "the back surface was not reconstructed".into());
        }
        for (name, why) in ["front", "back"].iter().zip(&s.withheld) {
            if let Some(why) = why {
                warn(page, format!("the {name} surface is not reported: {why}"));
            }
        }
        if s.station.is_none() {
            warn(page, s.uncertainty_note.clone());
        }
        if let Some(c) = s.consistency.as_ref().filter(|c| !c.consistent) {
            warn(
                page,
                format!("the result contradicts the station: {}", c.note),
            );
        }
    }
    if !any {
        page.fine("nothing to warn about");
    }
}

/// Both surfaces: figures, height map and coefficient chart.
///
/// # Errors
/// [`ReportError::Io`] when a picture cannot be read.
pub fn surfaces(page: &mut Page, dir: &Path, s: &Summary) -> Result<(), ReportError> {
    page.heading("Surfaces");
    page.note(&s.figures_note);
    let mut rows = Vec::new();
    let surfaces = [("front", Some(&s.front)), ("back", s.back.as_ref())];
    for ((name, f), withheld) in surfaces.into_iter().zip(&s.withheld) {
        let Some(f) = f.filter(|_| withheld.is_none()) else {
            rows.push(vec![name.into(), "not reconstructed".into()]);
            continue;
        };
        rows.push(vec![
            name.into(),
            f.terms.to_string(),
            format!("{:.3} ± {:.3}", f.rms_nm, f.rms_std_nm),
            format!("{:.2}", f.pv_nm),
            format!("{:.3}", f.error_rms_nm),
        ]);
    }
    page.table(
        &[
            "surface",
            "Zernike terms",
            "RMS ± σ, nm",
            "PV, nm",
            "expected error RMS, nm",
        ],
        &rows,
    );
    for name in ["front", "back"] {
        if let Some(png) = read(&dir.join(format!("{name}.png")))? {
            page.png(&png, &format!("{name} surface height map (nm, axes mm)"));
        }
        if let Some(png) = read(&dir.join(format!("{name}_coefficients.png")))? {
            page.png(
                &png,
                &format!("{name} surface Zernike coefficients with ±1σ"),
            );
        }
    }
    Ok(())
}

/// The uncertainty and its budget where a station uncertainty was used.
///
/// # Errors
/// [`ReportError::Io`] when the breakdown picture cannot be read.
pub fn uncertainty(page: &mut Page, dir: &Path, s: &Summary) -> Result<(), ReportError> {
    page.heading("Uncertainty");
    page.paragraph(&s.uncertainty_note);
    if let Some(st) = &s.station {
        page.note(&st.note);
        let mut rows = Vec::new();
        for (name, split) in [("front", Some(&st.front)), ("back", st.back.as_ref())] {
            if let Some(e) = split {
                rows.push(vec![
                    name.into(),
                    format!("{:.3}", e.noise_rms_nm),
                    format!("{:.3}", e.station_rms_nm),
                    format!("{:.3}", e.total_rms_nm),
                ]);
            }
        }
        page.table(&["surface", "noise, nm", "station, nm", "total, nm"], &rows);
        let rows: Vec<Vec<String>> = st
            .largest
            .iter()
            .map(|d| {
                vec![
                    d.name.clone(),
                    format!("{:.3e}", d.std),
                    format!("{:.3} ({:.0} %)", d.front_rms_nm, 100.0 * d.front_share),
                    format!("{:.3} ({:.0} %)", d.back_rms_nm, 100.0 * d.back_share),
                ]
            })
            .collect();
        page.table(&["degree of freedom", "1σ", "front, nm", "back, nm"], &rows);
    }
    if let Some(png) = read(&dir.join("uncertainty_breakdown.png"))? {
        page.png(&png, "1σ per Zernike term: noise and station");
    }
    Ok(())
}

/// Which estimator made the surfaces, in words.
fn estimator(s: &Summary) -> String {
    match &s.direct {
        Some(d) => format!(
            "surfaces fitted to the frames (surface-domain): {} iterations, {}",
            d.iterations.len(),
            if d.converged {
                "converged"
            } else {
                "did not converge"
            }
        ),
        None => "per-pixel screen points, then the surfaces".into(),
    }
}

/// The surface fit: pixels, stages, χ², condition number.
pub fn fit(page: &mut Page, s: &Summary) {
    page.heading("Surface fit");
    page.table(
        &["", ""],
        &[
            vec!["estimator".into(), estimator(s)],
            vec![
                "pixels with S1 / S2".into(),
                format!("{} / {}", s.pixels.s1, s.pixels.s2),
            ],
            vec!["outliers".into(), s.outliers.count.to_string()],
            vec!["residual components".into(), s.residuals.to_string()],
            vec!["χ²/dof".into(), format!("{:.4}", s.reduced_chi2)],
            vec![
                "condition number".into(),
                format!("{:.3e}", s.condition_number),
            ],
            vec![
                "σ of the screen points from the data".into(),
                s.sigma_from_data.to_string(),
            ],
            vec!["term choice".into(), s.terms.criterion.clone()],
        ],
    );
    let rows: Vec<Vec<String>> = s
        .stages
        .iter()
        .map(|st| {
            let what = match &st.detail {
                StageDetail::Slopes(d) => format!(
                    "{} iterations, last change {:.3e} nm, {} points",
                    d.iterations, d.last_change_nm, d.points
                ),
                StageDetail::LeastSquares(d) => format!(
                    "{} iterations, χ² {:.4e} → {:.4e}, {}",
                    d.iterations, d.chi2_start, d.chi2, d.reason
                ),
                StageDetail::Timed {} => String::new(),
            };
            vec![st.name.clone(), format!("{:.2}", st.seconds), what]
        })
        .collect();
    page.table(&["stage", "s", "figures"], &rows);
}

/// The spectral stage: flag counts and quality maps.
pub fn spectral(page: &mut Page, flags: Option<&FlagCounts>, maps: Vec<Picture>) {
    page.heading("Spectral stage");
    match flags {
        Some((with_data, counts)) => {
            let rows: Vec<Vec<String>> = counts
                .iter()
                .map(|(name, n)| vec![name.to_string(), n.to_string()])
                .collect();
            page.paragraph(&format!(
                "{with_data} camera pixels with data; pixels per flag:"
            ));
            page.table(&["flag", "pixels"], &rows);
        }
        None => page.paragraph("No flags.npy: the spectral stage did not run here."),
    }
    for m in maps {
        page.png(&m.png, &m.caption);
    }
}

/// The comparison with an interferometer: registration, the coefficients
/// term by term, the RMS of the difference, the pictures.
///
/// # Errors
/// [`ReportError`] when a picture cannot be drawn.
pub fn comparison(page: &mut Page, c: &Comparison) -> Result<(), ReportError> {
    page.heading(&format!(
        "Comparison with the interferometer ({})",
        c.surface
    ));
    for line in c.describe() {
        page.paragraph(&line);
    }
    let rows: Vec<Vec<String>> = c.table_rows();
    page.table(
        &[
            "Noll j",
            "mfd, nm",
            "mfd σ, nm",
            "interferometer, nm",
            "mfd − interferometer, nm",
            "difference / σ",
        ],
        &rows,
    );
    let scratch = super::Scratch::new()?;
    for (path, caption) in crate::compare::pictures::draw(&scratch.0, c)? {
        if let Some(png) = read(&path)? {
            page.png(&png, &caption);
        }
    }
    Ok(())
}
