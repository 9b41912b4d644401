//! PNG pictures of the surface stage: height maps with colour bars in nm
//! and coefficient charts with ±σ error bars (piston and tilt removed).

use std::path::Path;

use mfd::report::plot::{coefficient_chart_png, height_map_png};
use mfd::solve::surfaces::report::{SurfaceFigures, REMOVED_TERMS};

fn title_case(name: &str) -> String {
    let mut c = name.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

/// `DIR/{name}.png`: the height map (`n × n`, nm) with its colour bar.
pub fn surface(
    out: &Path,
    name: &str,
    grid: &[f64],
    n: usize,
    f: &SurfaceFigures,
) -> anyhow::Result<()> {
    let title = format!(
        "{} surface, piston and tilt removed: RMS {:.2} nm, PV {:.1} nm, {} terms",
        title_case(name),
        f.rms_nm,
        f.pv_nm,
        f.terms
    );
    height_map_png(&out.join(format!("{name}.png")), grid, n, n, &title, "nm")?;
    Ok(())
}

/// `DIR/{name}_coefficients.png`: coefficients from Noll j = 4 with ±σ.
pub fn coefficients(out: &Path, name: &str, f: &SurfaceFigures) -> anyhow::Result<()> {
    let title = format!(
        "{} surface Zernike coefficients (Noll j >= {}), error bars 1 sigma",
        title_case(name),
        REMOVED_TERMS + 1
    );
    let skip = REMOVED_TERMS.min(f.coefficients_nm.len());
    if skip == f.coefficients_nm.len() {
        // The model chose piston and tilt alone: nothing beyond them to chart.
        println!("{name}: no Zernike terms beyond tilt, no {name}_coefficients.png");
        return Ok(());
    }
    coefficient_chart_png(
        &out.join(format!("{name}_coefficients.png")),
        &f.coefficients_nm[skip..],
        &f.std_nm[skip..],
        skip + 1,
        &title,
    )?;
    Ok(())
}
