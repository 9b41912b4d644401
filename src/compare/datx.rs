//! Zygo `.datx` files (HDF5; cargo feature `datx`, the HDF5 C library
//! through `hdf5-metno`): the surface is the first dataset of the group
//! `/Data/Surface`, a 2-D float array (row 0 at the top), with these
//! attributes on the dataset:
//!
//! | attribute                      | type   | meaning |
//! |--------------------------------|--------|---------|
//! | `Unit`                         | string | `Fringes`/`Waves`, or a length: `nm`/`NanoMeters`, `um`/`MicroMeters`, `mm`/`MilliMeters`, `m`/`Meters` |
//! | `Wavelength`                   | f64    | metres (needed for `Fringes`) |
//! | `Interferometric Scale Factor` | f64    | S (applies to `Fringes`; default 1) |
//! | `Obliquity Factor`             | f64    | O (applies to `Fringes`; default 1) |
//! | `Lateral Resolution`           | f64    | metres per pixel (optional) |
//! | `No Data`                      | f64    | the value of pixels without data (optional; NaN always is) |
//!
//! A height in fringes is `value · W · S · O`; a height in a length unit is
//! already one.

use std::path::Path;

use hdf5::types::{VarLenAscii, VarLenUnicode};

use super::{CompareError, InterferometerMap};

/// The group that holds the surface.
pub const SURFACE_GROUP: &str = "Data/Surface";

fn h5err<'a>(path: &'a Path, item: &str) -> impl Fn(hdf5::Error) -> CompareError + 'a {
    let item = item.to_string();
    move |e| CompareError::Content {
        path: path.to_path_buf(),
        item: item.clone(),
        reason: e.to_string(),
    }
}

/// A string attribute (variable-length UTF-8 or ASCII, as h5py and Zygo
/// write them).
fn string_attr(ds: &hdf5::Dataset, path: &Path, name: &str) -> Result<String, CompareError> {
    let attr = ds
        .attr(name)
        .map_err(h5err(path, &format!("{SURFACE_GROUP} attribute {name}")))?;
    if let Ok(s) = attr.read_scalar::<VarLenUnicode>() {
        return Ok(s.as_str().to_string());
    }
    attr.read_scalar::<VarLenAscii>()
        .map(|s| s.as_str().to_string())
        .map_err(h5err(
            path,
            &format!("{SURFACE_GROUP} attribute {name} (a string)"),
        ))
}

/// A number attribute, `None` when absent.
fn number_attr(ds: &hdf5::Dataset, path: &Path, name: &str) -> Result<Option<f64>, CompareError> {
    let Ok(attr) = ds.attr(name) else {
        return Ok(None);
    };
    let v = attr.read_scalar::<f64>().map_err(h5err(
        path,
        &format!("{SURFACE_GROUP} attribute {name} (a number)"),
    ))?;
    Ok(Some(v))
}

/// nm per stored value for `unit`, `None` for fringes.
fn length_unit_nm(unit: &str) -> Option<f64> {
    match unit.to_ascii_lowercase().as_str() {
        "nm" | "nanometers" | "nanometres" => Some(1.0),
        "um" | "µm" | "micrometers" | "micrometres" | "microns" => Some(1e3),
        "mm" | "millimeters" | "millimetres" => Some(1e6),
        "m" | "meters" | "metres" => Some(1e9),
        _ => None,
    }
}

/// Reads the surface of a `.datx` file as heights.
///
/// # Errors
/// [`CompareError::Content`] naming the group, dataset or attribute that is
/// missing or not what the layout above says.
pub fn read(path: &Path) -> Result<InterferometerMap, CompareError> {
    let file = hdf5::File::open(path).map_err(h5err(path, "HDF5 file"))?;
    let group = file
        .group(SURFACE_GROUP)
        .map_err(h5err(path, SURFACE_GROUP))?;
    let names = group.member_names().map_err(h5err(path, SURFACE_GROUP))?;
    let Some(name) = names.first() else {
        return Err(CompareError::Content {
            path: path.to_path_buf(),
            item: SURFACE_GROUP.into(),
            reason: "no dataset in the group".into(),
        });
    };
    let item = format!("{SURFACE_GROUP}/{name}");
    let ds = group.dataset(name).map_err(h5err(path, &item))?;
    let data = ds.read_2d::<f64>().map_err(h5err(path, &item))?;
    let (height, width) = data.dim();
    let unit = string_attr(&ds, path, "Unit")?;
    let wavelength_m = number_attr(&ds, path, "Wavelength")?;
    let scale = match length_unit_nm(&unit) {
        Some(s) => s,
        None if matches!(unit.to_ascii_lowercase().as_str(), "fringes" | "waves") => {
            let Some(w) = wavelength_m.filter(|w| *w > 0.0) else {
                return Err(CompareError::Content {
                    path: path.to_path_buf(),
                    item: format!("{SURFACE_GROUP} attribute Wavelength"),
                    reason: "missing or not positive: heights in fringes need it (metres)".into(),
                });
            };
            let s = number_attr(&ds, path, "Interferometric Scale Factor")?.unwrap_or(1.0);
            let o = number_attr(&ds, path, "Obliquity Factor")?.unwrap_or(1.0);
            w * s * o * 1e9
        }
        None => {
            return Err(CompareError::Content {
                path: path.to_path_buf(),
                item: format!("{SURFACE_GROUP} attribute Unit"),
                reason: format!(
                    "{unit:?}, expected Fringes, Waves, nm, um, mm or m (or their long names)"
                ),
            })
        }
    };
    let no_data = number_attr(&ds, path, "No Data")?;
    let heights_nm = data
        .iter()
        .map(|&v| {
            if !v.is_finite() || no_data == Some(v) {
                f64::NAN
            } else {
                v * scale
            }
        })
        .collect();
    let lateral = number_attr(&ds, path, "Lateral Resolution")?.filter(|p| *p > 0.0);
    Ok(InterferometerMap {
        path: path.to_path_buf(),
        format: "Zygo .datx",
        width,
        height,
        heights_nm,
        pixel_mm: lateral.map(|p| p * 1e3),
        wavelength_nm: wavelength_m.map(|w| w * 1e9),
    })
}
