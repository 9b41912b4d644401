//! The report's first block, what an optician reads first: what was
//! removed, the figures with their σ (`summary.json`'s `figures`), each
//! face's ISO 10110-5 form notation at a stated wavelength, and the maps
//! of the plate's thickness variation and transmitted wavefront.

use std::path::Path;

use super::{Page, ReportError};
use crate::formats::surfaces_file::SurfacesFile;
use crate::optics::zernike::{noll_to_nm, ZernikeBasis, ZernikeSurface};
use crate::plot::{height_map, Extent, Format, HeightMap};
use crate::report::figures::{difference, FaceFigures, Figures};
use crate::report::repeatability::Repeatability;
use crate::report::summary::Summary;
use crate::solve::surfaces::report::height_grid;

/// ISO 10110-5's default wavelength for fringe spacings (the mercury e
/// line), nm: the notation's fringes are of half of it.
pub const ISO_WAVELENGTH_NM: f64 = 546.07;

/// Side of the maps' grids, pixels.
const MAP_SIDE: usize = 256;

/// Samples along the radius for the rotationally symmetric irregularity.
const RADIAL_SAMPLES: usize = 1001;

/// The result block: figures, notation and maps; `scratch` a folder to
/// draw the maps in.
///
/// # Errors
/// [`ReportError`] when `surfaces.json` cannot be read or a map drawn.
pub fn result_block(
    page: &mut Page,
    dir: &Path,
    summary: &Summary,
    scratch: &Path,
) -> Result<(), ReportError> {
    page.heading("Result");
    let Some(f) = &summary.figures else {
        page.note("summary.json has no figures (written before mfd reported them).");
        return Ok(());
    };
    page.note(&format!("Removed: {}.", f.removed));
    page.note(&format!("σ: {}; {}.", f.covariance, method(f)));
    faces(page, f, dir)?;
    plate(page, f);
    repeatability(page, dir)?;
    maps(page, f, dir, scratch)
}

/// The repeatability of `mfd measure --repeat` (its `repeatability.json`
/// two folders up, `OUT/run-K/result`), when this result is one of its runs.
fn repeatability(page: &mut Page, dir: &Path) -> Result<(), ReportError> {
    let Some(path) = dir
        .parent()
        .and_then(Path::parent)
        .map(|d| d.join("repeatability.json"))
        .filter(|p| p.is_file())
    else {
        return Ok(());
    };
    let text = std::fs::read_to_string(&path).map_err(|source| ReportError::Io {
        path: path.clone(),
        source,
    })?;
    let r: Repeatability =
        serde_json::from_str(&text).map_err(|source| ReportError::Json { path, source })?;
    let mut rows = Vec::new();
    for (name, s) in [("front", &r.front), ("back", &r.back)] {
        if let Some(s) = s {
            rows.push(vec![
                name.to_string(),
                format!("{:.3}", s.departure_rms_nm),
                format!("{:.3}", s.mean_expected_error_rms_nm),
                format!("{:.2}", s.spread_over_reported),
            ]);
        }
    }
    page.paragraph(&format!(
        "Repeatability over {} runs (mfd measure --repeat; repeatability.json): each surface's \
         spread over the runs (piston and tilt removed) against the error each run reported.",
        r.runs
    ));
    page.table(
        &[
            "surface",
            "spread RMS, nm",
            "mean reported error RMS, nm",
            "spread over reported",
        ],
        &rows,
    );
    Ok(())
}

fn method(f: &Figures) -> String {
    let drawn = f
        .std_method
        .get("rms_t_std_nm")
        .cloned()
        .unwrap_or_default();
    format!("power linear, every other σ by {drawn}")
}

fn pm(v: f64, s: f64) -> String {
    format!("{v:.2} ± {s:.2}")
}

/// The faces' table and each face's ISO 10110-5 notation.
fn faces(page: &mut Page, f: &Figures, dir: &Path) -> Result<(), ReportError> {
    let surfaces = SurfacesFile::load(&dir.join("surfaces.json")).ok();
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    for (k, (name, face)) in [("front", &f.front), ("back", &f.back)]
        .into_iter()
        .enumerate()
    {
        let Some(x) = face else {
            let why = f.why_null[k].as_deref().unwrap_or("not reported");
            rows.push(vec![name.to_string(), format!("not reported: {why}")]);
            continue;
        };
        rows.push(vec![
            name.to_string(),
            pm(x.power_nm, x.power_std_nm),
            pm(x.irregularity_pv_nm, x.irregularity_pv_std_nm),
            pm(x.rms_t_nm, x.rms_t_std_nm),
            pm(x.rms_i_nm, x.rms_i_std_nm),
            pm(x.rms_a_nm, x.rms_a_std_nm),
        ]);
        let coefficients = surfaces.as_ref().and_then(|s| {
            if k == 0 {
                s.front_coefficients()
            } else {
                s.back_coefficients()
            }
        });
        let radius = surfaces.as_ref().map(|s| s.zernike.radius_mm);
        let c = match (coefficients, radius) {
            (Some(c), Some(r)) => rotational_irregularity_pv_nm(c, r),
            _ => None,
        };
        notes.push(format!("{name}: {}", iso_notation(x, c)));
    }
    page.table(
        &[
            "face",
            "power, nm",
            "irregularity PV, nm",
            "RMSt, nm",
            "RMSi, nm",
            "RMSa, nm",
        ],
        &rows,
    );
    page.paragraph(&format!(
        "ISO 10110-5 form of each face as measured, in fringes of λ/2 at λ = {ISO_WAVELENGTH_NM} nm \
         (A: power, signed as a4; B: irregularity PV; C: its rotationally symmetric part's PV, \
         Noll m = 0 from n = 4, without σ):"
    ));
    for n in notes {
        page.paragraph(&n);
    }
    Ok(())
}

/// `3/A(B/C) RMSt D; RMSi E; RMSa F; λ = 546.07 nm` of the measured face,
/// in fringes (λ/2); C as "-" where it is not known.
pub fn iso_notation(x: &FaceFigures, rotational_pv_nm: Option<f64>) -> String {
    let fringe = ISO_WAVELENGTH_NM / 2.0;
    let c = rotational_pv_nm.map_or("-".to_string(), |c| format!("{:.3}", c / fringe));
    format!(
        "3/{:.3}({:.3}/{c}) RMSt {:.4}; RMSi {:.4}; RMSa {:.4}; λ = {ISO_WAVELENGTH_NM} nm",
        x.power_nm / fringe,
        x.irregularity_pv_nm / fringe,
        x.rms_t_nm / fringe,
        x.rms_i_nm / fringe,
        x.rms_a_nm / fringe,
    )
}

/// The PV (nm) along the radius of the rotationally symmetric terms from
/// n = 4 (Noll m = 0: spherical aberration and beyond) of coefficients
/// `c` on the radius `radius_mm`; `None` for an unusable radius.
pub fn rotational_irregularity_pv_nm(c: &[f64], radius_mm: f64) -> Option<f64> {
    let kept: Vec<f64> = c
        .iter()
        .enumerate()
        .map(|(k, &v)| match noll_to_nm(k + 1) {
            Ok((n, 0)) if n >= 4 => v,
            _ => 0.0,
        })
        .collect();
    let basis = ZernikeBasis::new(kept.len(), radius_mm, [0.0, 0.0]).ok()?;
    let s = ZernikeSurface::new(basis, kept).ok()?;
    let h: Vec<f64> = (0..RADIAL_SAMPLES)
        .map(|i| s.height_mm(radius_mm * i as f64 / (RADIAL_SAMPLES - 1) as f64, 0.0) * 1e6)
        .collect();
    let (lo, hi) = h
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    Some(hi - lo)
}

/// The plate's figures as name–value pairs.
fn plate(page: &mut Page, f: &Figures) {
    let Some(p) = &f.plate else {
        page.paragraph(&format!(
            "Plate: not reported: {}",
            f.why_null[2].as_deref().unwrap_or("")
        ));
        return;
    };
    page.pairs(&[
        vec![
            "wedge".into(),
            format!(
                "{} arcsec, thinning towards {} ° (element frame, from +x towards +y)",
                pm(p.wedge_arcsec, p.wedge_std_arcsec),
                pm(p.wedge_azimuth_deg, p.wedge_azimuth_std_deg)
            ),
        ],
        vec![
            "thickness variation (piston and tilt removed)".into(),
            format!(
                "PV {} nm, RMS {} nm",
                pm(p.thickness_variation_pv_nm, p.thickness_variation_pv_std_nm),
                pm(
                    p.thickness_variation_rms_nm,
                    p.thickness_variation_rms_std_nm
                )
            ),
        ],
        vec![
            format!(
                "transmitted wavefront (n − 1)(W1 − W2), n = {}, normal incidence",
                p.refractive_index
            ),
            format!(
                "RMS {} nm = {:.5} ± {:.5} waves at {} nm, PV {} nm",
                pm(p.twe_rms_nm, p.twe_rms_std_nm),
                p.twe_rms_waves,
                p.twe_rms_std_waves,
                p.wavelength_nm,
                pm(p.twe_pv_nm, p.twe_pv_std_nm)
            ),
        ],
    ]);
}

/// The thickness-variation and transmitted-wavefront maps (piston and tilt
/// removed) from `surfaces.json`, with colour bars.
fn maps(page: &mut Page, f: &Figures, dir: &Path, scratch: &Path) -> Result<(), ReportError> {
    let Some(p) = &f.plate else { return Ok(()) };
    let s = SurfacesFile::load(&dir.join("surfaces.json"))?;
    let (Some(front), Some(back)) = (s.front_coefficients(), s.back_coefficients()) else {
        return Ok(());
    };
    let d = difference(front, back);
    let (r, [cx, cy]) = (s.zernike.radius_mm, s.zernike.center_mm);
    let Ok(basis) = ZernikeBasis::new(d.len(), r, [cx, cy]) else {
        return Ok(());
    };
    let Ok(surface) = ZernikeSurface::new(basis, d) else {
        return Ok(());
    };
    let tv = height_grid(&surface, &s.outline_in_place(), MAP_SIDE);
    let twe: Vec<f64> = tv.iter().map(|v| v * (p.refractive_index - 1.0)).collect();
    let extent = Extent {
        x_mm: (cx - r, cx + r),
        y_mm: (cy - r, cy + r),
    };
    for (name, values, title) in [
        (
            "thickness_variation",
            &tv,
            format!(
                "Thickness variation W1 - W2, piston and tilt removed: PV {:.1} nm, RMS {:.2} nm",
                p.thickness_variation_pv_nm, p.thickness_variation_rms_nm
            ),
        ),
        (
            "transmitted_wavefront",
            &twe,
            format!(
                "Transmitted wavefront (n - 1)(W1 - W2), n = {}: PV {:.1} nm, RMS {:.2} nm",
                p.refractive_index, p.twe_pv_nm, p.twe_rms_nm
            ),
        ),
    ] {
        let path = scratch.join(format!("{name}.png"));
        let map = HeightMap {
            values,
            width: MAP_SIDE,
            height: MAP_SIDE,
            title: &title,
            unit: "nm",
            extent: Some(extent),
        };
        height_map(&path, Format::Png, &map)?;
        let png = std::fs::read(&path).map_err(|source| ReportError::Io {
            path: path.clone(),
            source,
        })?;
        page.png(&png, &format!("{} (nm, axes mm)", name.replace('_', " ")));
    }
    Ok(())
}
