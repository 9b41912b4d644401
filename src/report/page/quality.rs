//! The spectral stage's quality maps for the report, drawn from the arrays
//! a result folder holds (`screen_std.npy`, `residual_rms.npy`,
//! `separation_bins.npy`, `tau_max.npy`) and the count of every flag of
//! `flags.npy`.

use std::path::Path;

use super::ReportError;
use crate::formats::npy;
use crate::plot::height_map_png;
use crate::solve::spectral::PixelFlags;

/// Pixels with data, and per flag (its meaning) the pixels that have it.
pub type FlagCounts = (usize, Vec<(&'static str, usize)>);

/// A map to draw: what it shows (", unit" at the end), rows, columns, values.
type NamedMap = (String, usize, usize, Vec<f64>);

/// One drawn map: its PNG and caption.
pub struct Picture {
    /// The PNG file's bytes.
    pub png: Vec<u8>,
    /// What it shows.
    pub caption: String,
}

/// A `[rows, columns]` map of `dir/name` when the file exists.
fn scalar_map(dir: &Path, name: &str) -> Result<Option<(usize, usize, Vec<f64>)>, ReportError> {
    let path = dir.join(name);
    if !path.is_file() {
        return Ok(None);
    }
    let (shape, v) = npy::read_f64(&path)?;
    if shape.len() != 2 {
        return Err(ReportError::Shape {
            path,
            expected: "[rows, columns]",
            found: shape,
        });
    }
    Ok(Some((shape[0], shape[1], v)))
}

/// σ of each reflection's screen point (root sum of squares of σ_u, σ_v)
/// from `screen_std.npy` (`[rows, columns, 2, 2]`).
fn sigma_maps(dir: &Path) -> Result<Vec<NamedMap>, ReportError> {
    let path = dir.join("screen_std.npy");
    if !path.is_file() {
        return Ok(Vec::new());
    }
    let (shape, v) = npy::read_f64(&path)?;
    if shape.len() != 4 || shape[2..] != [2, 2] {
        return Err(ReportError::Shape {
            path,
            expected: "[rows, columns, 2, 2]",
            found: shape,
        });
    }
    let (h, w) = (shape[0], shape[1]);
    let mut out = Vec::new();
    for (k, name) in ["S1 (front)", "S2 (back)"].into_iter().enumerate() {
        let m = (0..h * w)
            .map(|p| v[p * 4 + 2 * k].hypot(v[p * 4 + 2 * k + 1]))
            .collect();
        out.push((format!("σ of {name}, screen px"), h, w, m));
    }
    Ok(out)
}

/// Draws every quality map the folder has, through `scratch` (a folder of
/// its own that the caller removes).
///
/// # Errors
/// [`ReportError`] naming the array that could not be read or the picture
/// that could not be drawn.
pub fn maps(dir: &Path, scratch: &Path) -> Result<Vec<Picture>, ReportError> {
    let mut maps = sigma_maps(dir)?;
    for (file, what) in [
        (
            "residual_rms.npy",
            "RMS residual of the spectral fit, counts",
        ),
        (
            "separation_bins.npy",
            "separation of the two reflections, Fourier bins",
        ),
        ("tau_max.npy", "modulation falloff τ_max"),
    ] {
        if let Some((h, w, v)) = scalar_map(dir, file)? {
            maps.push((what.to_string(), h, w, v));
        }
    }
    let mut out = Vec::new();
    for (i, (what, h, w, v)) in maps.into_iter().enumerate() {
        let unit = what.rsplit(", ").next().unwrap_or("").to_string();
        let title = what.split(", ").next().unwrap_or(&what).to_string();
        let path = scratch.join(format!("quality_{i}.png"));
        height_map_png(&path, &v, w, h, &title, &unit)?;
        let png = std::fs::read(&path).map_err(|source| ReportError::Io {
            path: path.clone(),
            source,
        })?;
        out.push(Picture {
            png,
            caption: format!("{what} per camera pixel ({w} × {h})"),
        });
    }
    Ok(out)
}

/// Pixel counts per flag of `flags.npy` (pixels with data only), with the
/// number of pixels that have data; `None` without the file.
///
/// # Errors
/// [`ReportError::Npy`] when the file cannot be read.
pub fn flag_counts(dir: &Path) -> Result<Option<FlagCounts>, ReportError> {
    let path = dir.join("flags.npy");
    if !path.is_file() {
        return Ok(None);
    }
    let (_, flags) = npy::read_u16(&path)?;
    let with_data: Vec<PixelFlags> = flags
        .into_iter()
        .map(PixelFlags::from_bits_truncate)
        .filter(|f| !f.intersects(PixelFlags::NO_DATA))
        .collect();
    let counts = PixelFlags::MEANINGS
        .into_iter()
        .filter(|(bit, _)| *bit != PixelFlags::NO_DATA)
        .map(|(bit, name)| (name, with_data.iter().filter(|f| f.intersects(bit)).count()))
        .collect();
    Ok(Some((with_data.len(), counts)))
}
