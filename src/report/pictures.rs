//! The surface stage's pictures: each surface's height map with its colour
//! bar in nm, its Zernike coefficients from Noll j = 4 with ±1σ error bars
//! (piston and tilt removed, as in every figure), and the uncertainty's
//! breakdown per Zernike term (noise against station, front and back).

use std::path::{Path, PathBuf};

use super::summary::Summary;
use crate::optics::zernike::ZernikeSurface;
use crate::plot::{
    coefficient_chart_png, height_map, line_plot_png, Extent, Format, HeightMap, Panel, PlotError,
    Series,
};
use crate::solve::surfaces::report::{SurfaceFigures, REMOVED_TERMS};

/// The breakdown chart's last Noll term (radial order 7; beyond it the
/// terms are the fit's tail, not what an operator calibrates for).
pub const BREAKDOWN_LAST_TERM: usize = 36;

fn title_case(name: &str) -> String {
    let mut c = name.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

/// `DIR/{name}.png`: the height map (`n × n` grid of nm over the
/// aperture's bounding square of `surface`, as
/// [`crate::solve::surfaces::report::height_grid`] makes it; NaN outside the
/// aperture) with its colour bar in nm and axes in mm; returns the file
/// written.
///
/// # Errors
/// [`PlotError`] when the picture cannot be drawn or written.
pub fn surface(
    out: &Path,
    name: &str,
    surface: &ZernikeSurface,
    grid: &[f64],
    n: usize,
    f: &SurfaceFigures,
) -> Result<PathBuf, PlotError> {
    let title = format!(
        "{} surface, piston and tilt removed: RMS {:.2} nm, PV {:.1} nm, {} terms",
        title_case(name),
        f.rms_nm,
        f.pv_nm,
        f.terms
    );
    let (r, [cx, cy]) = (surface.basis().radius_mm(), surface.basis().center_mm());
    let map = HeightMap {
        values: grid,
        width: n,
        height: n,
        title: &title,
        unit: "nm",
        extent: Some(Extent {
            x_mm: (cx - r, cx + r),
            y_mm: (cy - r, cy + r),
        }),
    };
    let path = out.join(format!("{name}.png"));
    height_map(&path, Format::Png, &map)?;
    Ok(path)
}

/// `DIR/{name}_coefficients.png`: coefficients from Noll j = 4 with ±1σ
/// (`total_std_nm`, noise and station, where the station's part is given;
/// else the noise's `f.std_nm`); `None` when the model has no term beyond
/// piston and tilt.
///
/// # Errors
/// [`PlotError`] when the picture cannot be drawn or written.
pub fn coefficients(
    out: &Path,
    name: &str,
    f: &SurfaceFigures,
    total_std_nm: Option<&[f64]>,
) -> Result<Option<PathBuf>, PlotError> {
    let skip = REMOVED_TERMS.min(f.coefficients_nm.len());
    if skip == f.coefficients_nm.len() {
        log::info!("{name}: no Zernike terms beyond tilt, no {name}_coefficients.png");
        return Ok(None);
    }
    let what = if total_std_nm.is_some() {
        " (noise and station)"
    } else {
        ""
    };
    let title = format!(
        "{} surface Zernike coefficients (Noll j ≥ {}), error bars ±1σ{what}",
        title_case(name),
        REMOVED_TERMS + 1
    );
    let std = total_std_nm.unwrap_or(&f.std_nm);
    let path = out.join(format!("{name}_coefficients.png"));
    coefficient_chart_png(
        &path,
        &f.coefficients_nm[skip..],
        &std[skip.min(std.len())..],
        skip + 1,
        &title,
    )?;
    Ok(Some(path))
}

/// A series' legend label and its points (Noll j, σ nm).
type Labelled = (&'static str, Vec<(f64, f64)>);

/// The breakdown's floor, a fraction of each panel's largest σ.
const BREAKDOWN_FLOOR: f64 = 1e-6;

/// `DIR/uncertainty_breakdown.png`: per Zernike term j = 4 … min(n, 36) the
/// 1σ from the imaging noise and from the station's geometry (and both
/// together), a panel per reconstructed surface, on a logarithmic σ axis.
/// Without a station part the title says the geometry was taken as exact
/// and only the noise is drawn. `None` when no surface has a term beyond
/// tilt.
///
/// # Errors
/// [`PlotError`] when the picture cannot be drawn or written.
pub fn breakdown(out: &Path, summary: &Summary) -> Result<Option<PathBuf>, PlotError> {
    let station = summary.station.as_ref();
    let surfaces = [
        ("front", Some(&summary.front), station.map(|s| &s.front)),
        (
            "back",
            summary.back.as_ref(),
            station.and_then(|s| s.back.as_ref()),
        ),
    ];
    let points = |std: &[f64]| -> Vec<(f64, f64)> {
        let last = std.len().min(BREAKDOWN_LAST_TERM);
        (REMOVED_TERMS..last)
            .map(|k| ((k + 1) as f64, std[k]))
            .collect()
    };
    let mut titles = Vec::new();
    let mut data: Vec<Vec<Labelled>> = Vec::new();
    for (name, figures, split) in surfaces {
        let Some(f) = figures.filter(|f| f.std_nm.len() > REMOVED_TERMS) else {
            continue;
        };
        let mut series = vec![("imaging noise", points(&f.std_nm))];
        let title = match split {
            Some(s) => {
                series.push(("station geometry", points(&s.station_std_nm)));
                series.push(("total", points(&s.total_std_nm)));
                format!(
                    "{}: noise {:.2} ⊕ station {:.2} = {:.2} nm RMS",
                    title_case(name),
                    s.noise_rms_nm,
                    s.station_rms_nm,
                    s.total_rms_nm
                )
            }
            None => format!(
                "{}: noise {:.2} nm RMS; geometry taken as exact",
                title_case(name),
                f.error_rms_nm
            ),
        };
        // A log axis spans what matters: σ below 1e-6 of the panel's
        // largest (rounding, or a term no degree of freedom reaches) are
        // drawn at that floor, not 14 decades down.
        let top = series
            .iter()
            .flat_map(|(_, p)| p.iter().map(|q| q.1))
            .fold(0.0_f64, f64::max);
        let floor = top * BREAKDOWN_FLOOR;
        for (_, p) in &mut series {
            for q in p.iter_mut() {
                q.1 = q.1.max(floor);
            }
        }
        titles.push(title);
        data.push(series);
    }
    if data.is_empty() {
        log::info!("no Zernike terms beyond tilt: no uncertainty_breakdown.png");
        return Ok(None);
    }
    let series: Vec<Vec<Series>> = data
        .iter()
        .map(|d| {
            d.iter()
                .map(|(label, points)| Series { label, points })
                .collect()
        })
        .collect();
    let panels: Vec<Panel> = titles
        .iter()
        .zip(&series)
        .map(|(title, series)| Panel {
            title,
            x_label: "Noll j",
            y_label: "1σ (nm)",
            log_x: false,
            log_y: true,
            series,
        })
        .collect();
    let path = out.join("uncertainty_breakdown.png");
    line_plot_png(&path, &panels)?;
    Ok(Some(path))
}
