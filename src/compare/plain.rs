//! Plain height maps: a NumPy `.npy` (float64, `[rows, columns]`) or a CSV
//! file of rows of numbers (`#` starts a comment line; an empty field,
//! `nan` or `NaN` is a pixel without data). Neither says its pixel size:
//! give it (`--pixel-mm`) or let the registration set it from the
//! aperture.

use std::path::Path;

use super::{CompareError, InterferometerMap};
use crate::formats::npy;

/// Reads a `[rows, columns]` float64 NPY map; values × `scale_nm` are nm.
///
/// # Errors
/// [`CompareError::Npy`] for the file, [`CompareError::Content`] for its shape.
pub fn read_npy(path: &Path, scale_nm: f64) -> Result<InterferometerMap, CompareError> {
    let (shape, v) = npy::read_f64(path)?;
    if shape.len() != 2 || shape[0] == 0 || shape[1] == 0 {
        return Err(CompareError::Content {
            path: path.to_path_buf(),
            item: "array".into(),
            reason: format!("shape {shape:?}, expected [rows, columns]"),
        });
    }
    Ok(InterferometerMap {
        path: path.to_path_buf(),
        format: "NPY",
        width: shape[1],
        height: shape[0],
        heights_nm: v.into_iter().map(|x| x * scale_nm).collect(),
        pixel_mm: None,
        wavelength_nm: None,
    })
}

/// Reads a CSV map; values × `scale_nm` are nm.
///
/// # Errors
/// [`CompareError::Csv`] naming the line of a field that is not a number or
/// a row of another length.
pub fn read_csv(path: &Path, scale_nm: f64) -> Result<InterferometerMap, CompareError> {
    let io = |source| CompareError::Io {
        path: path.to_path_buf(),
        source,
    };
    // A link to a device would be read until memory runs out.
    if !std::fs::metadata(path).map_err(io)?.is_file() {
        return Err(CompareError::Length {
            path: path.to_path_buf(),
            problem: "not a plain file (a device, a pipe or a folder)".into(),
        });
    }
    let text = std::fs::read_to_string(path).map_err(io)?;
    let (mut width, mut rows, mut heights_nm) = (0, 0, Vec::new());
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let before = heights_nm.len();
        for field in line.split(',') {
            let f = field.trim();
            let v = if f.is_empty() || f.eq_ignore_ascii_case("nan") {
                f64::NAN
            } else {
                f.parse::<f64>().map_err(|_| CompareError::Csv {
                    path: path.to_path_buf(),
                    line: i + 1,
                    reason: format!("{f:?} is not a number"),
                })?
            };
            heights_nm.push(v * scale_nm);
        }
        let n = heights_nm.len() - before;
        if rows == 0 {
            width = n;
        } else if n != width {
            return Err(CompareError::Csv {
                path: path.to_path_buf(),
                line: i + 1,
                reason: format!("{n} values, the first row has {width}"),
            });
        }
        rows += 1;
    }
    if rows == 0 {
        return Err(CompareError::Csv {
            path: path.to_path_buf(),
            line: 1,
            reason: "no rows of numbers".into(),
        });
    }
    Ok(InterferometerMap {
        path: path.to_path_buf(),
        format: "CSV",
        width,
        height: rows,
        heights_nm,
        pixel_mm: None,
        wavelength_nm: None,
    })
}
