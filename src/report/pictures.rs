//! The surface stage's pictures: each surface's height map with its colour
//! bar in nm, and its Zernike coefficients from Noll j = 4 with ±1σ error
//! bars (piston and tilt removed, as in every figure).

use std::path::{Path, PathBuf};

use super::plot::{coefficient_chart_png, height_map, Extent, Format, HeightMap, PlotError};
use crate::optics::zernike::ZernikeSurface;
use crate::solve::surfaces::report::{SurfaceFigures, REMOVED_TERMS};

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

/// `DIR/{name}_coefficients.png`: coefficients from Noll j = 4 with ±1σ;
/// `None` when the model has no term beyond piston and tilt.
///
/// # Errors
/// [`PlotError`] when the picture cannot be drawn or written.
pub fn coefficients(
    out: &Path,
    name: &str,
    f: &SurfaceFigures,
) -> Result<Option<PathBuf>, PlotError> {
    let skip = REMOVED_TERMS.min(f.coefficients_nm.len());
    if skip == f.coefficients_nm.len() {
        log::info!("{name}: no Zernike terms beyond tilt, no {name}_coefficients.png");
        return Ok(None);
    }
    let title = format!(
        "{} surface Zernike coefficients (Noll j ≥ {}), error bars ±1σ",
        title_case(name),
        REMOVED_TERMS + 1
    );
    let path = out.join(format!("{name}_coefficients.png"));
    coefficient_chart_png(
        &path,
        &f.coefficients_nm[skip..],
        &f.std_nm[skip..],
        skip + 1,
        &title,
    )?;
    Ok(Some(path))
}
