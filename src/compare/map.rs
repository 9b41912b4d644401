//! An interferometer's height map as the comparison uses it, and the
//! reader chosen by the file's name.

use std::path::{Path, PathBuf};

use super::CompareError;

/// A height map: `heights_nm[row * width + column]`, row 0 at the top of
/// the instrument's picture (`+y`), column 0 at its left (`−x`); NaN where
/// the instrument measured nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct InterferometerMap {
    /// The file it was read from.
    pub path: PathBuf,
    /// Which reader read it (`MetroPro .dat`, `Zygo .datx`, `NPY`, `CSV`).
    pub format: &'static str,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Heights, nm.
    pub heights_nm: Vec<f64>,
    /// The pixel's size on the part, mm, when the file says it.
    pub pixel_mm: Option<f64>,
    /// The instrument's wavelength, nm, when the file says it.
    pub wavelength_nm: Option<f64>,
}

impl InterferometerMap {
    /// Pixels with a height.
    pub fn valid(&self) -> usize {
        self.heights_nm.iter().filter(|h| h.is_finite()).count()
    }
}

/// How to read maps whose files do not say everything (NPY, CSV).
#[derive(Debug, Clone, Copy)]
pub struct LoadOptions {
    /// Multiplies the stored values to give nm (NPY and CSV; 1 for maps in
    /// nm, 1e9 for maps in metres).
    pub height_scale_nm: f64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            height_scale_nm: 1.0,
        }
    }
}

/// Reads the map at `path`, the reader chosen by its extension (`.dat`,
/// `.datx`, `.npy`, `.csv`, case-insensitive).
///
/// # Errors
/// [`CompareError`] naming the file, and for headers the field.
pub fn load(path: &Path, options: &LoadOptions) -> Result<InterferometerMap, CompareError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("dat") => super::dat::read(path),
        Some("datx") => read_datx(path),
        Some("npy") => super::plain::read_npy(path, options.height_scale_nm),
        Some("csv") => super::plain::read_csv(path, options.height_scale_nm),
        _ => Err(CompareError::UnknownFormat {
            path: path.to_path_buf(),
        }),
    }
}

#[cfg(feature = "datx")]
fn read_datx(path: &Path) -> Result<InterferometerMap, CompareError> {
    super::datx::read(path)
}

#[cfg(not(feature = "datx"))]
fn read_datx(path: &Path) -> Result<InterferometerMap, CompareError> {
    Err(CompareError::NoDatx {
        path: path.to_path_buf(),
    })
}
