//! The comparison's pictures, as the paper shows them: mfd's map and the
//! interferometer's side by side, their difference (colour bars in nm,
//! axes in mm, piston and tilt removed), and the coefficients from Noll
//! j = 4 — mfd's with ±1σ, the interferometer's, and the difference with
//! mfd's ±1σ.

use std::path::{Path, PathBuf};

use super::{CompareError, Comparison};
use crate::plot::{coefficient_chart_png, height_map, Extent, Format, HeightMap, MAX_BARS};
use crate::solve::surfaces::report::REMOVED_TERMS;

/// Draws the pictures into `dir` (created if missing); returns each file
/// with its caption.
///
/// # Errors
/// [`CompareError::Io`] when `dir` cannot be made, [`CompareError::Plot`]
/// when a picture cannot be drawn.
pub fn draw(dir: &Path, c: &Comparison) -> Result<Vec<(PathBuf, String)>, CompareError> {
    std::fs::create_dir_all(dir).map_err(|source| CompareError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let m = &c.maps;
    let [x0, x1, y0, y1] = m.extent_mm;
    let extent = Extent {
        x_mm: (x0, x1),
        y_mm: (y0, y1),
    };
    let mut out = Vec::new();
    for (file, values, title) in [
        (
            "comparison_mfd.png",
            &m.mfd_nm,
            format!("mfd, {} surface", c.surface),
        ),
        (
            "comparison_interferometer.png",
            &m.interferometer_nm,
            "interferometer".to_string(),
        ),
        (
            "comparison_difference.png",
            &m.difference_nm,
            format!("mfd − interferometer: {:.3} nm RMS", c.difference_rms_nm),
        ),
    ] {
        let path = dir.join(file);
        let title = format!("{title} (piston and tilt removed)");
        let map = HeightMap {
            values,
            width: m.n,
            height: m.n,
            title: &title,
            unit: "nm",
            extent: Some(extent),
        };
        height_map(&path, Format::Png, &map)?;
        out.push((path, title));
    }
    let skip = REMOVED_TERMS.min(c.terms.len());
    let last = c.terms.len().min(skip + MAX_BARS);
    let terms = &c.terms[skip..last];
    if terms.is_empty() {
        return Ok(out);
    }
    let sigma: Vec<f64> = terms.iter().map(|t| t.mfd_std_nm.unwrap_or(0.0)).collect();
    let sigma = if terms.iter().all(|t| t.mfd_std_nm.is_some()) {
        sigma
    } else {
        Vec::new()
    };
    for (file, values, std, title) in [
        (
            "comparison_coefficients_mfd.png",
            terms.iter().map(|t| t.mfd_nm).collect::<Vec<_>>(),
            sigma.clone(),
            "mfd's Zernike coefficients, ±1σ",
        ),
        (
            "comparison_coefficients_interferometer.png",
            terms.iter().map(|t| t.interferometer_nm).collect(),
            Vec::new(),
            "the interferometer's Zernike coefficients (same terms, same aperture)",
        ),
        (
            "comparison_coefficients_difference.png",
            terms.iter().map(|t| t.difference_nm).collect(),
            sigma,
            "mfd − interferometer per term, with mfd's ±1σ",
        ),
    ] {
        let path = dir.join(file);
        coefficient_chart_png(&path, &values, &std, skip + 1, title)?;
        out.push((path, title.to_string()));
    }
    Ok(out)
}
