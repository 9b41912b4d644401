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
//!
//! **Bounded before it is read** (issue 37): the file must be a plain file
//! (a link to `/dev/zero` or a pipe is refused before HDF5 opens it), the
//! dataset two-dimensional, its values (read as f64) must fit in the memory
//! free now ([`crate::limits::check_fits`]), and, stored without a filter
//! (no compression), in the file itself: a header that claims more values
//! than the file holds is named, not answered with fill values.

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

/// Refuses the dataset `ds` (`item` of `path`, a file of `file_len` bytes)
/// before its values are read: not 2-D, more values (as f64) than the
/// memory free holds, or, stored unfiltered, more than the file holds.
fn bounded(ds: &hdf5::Dataset, path: &Path, item: &str, file_len: u64) -> Result<(), CompareError> {
    let content = |reason: String| CompareError::Content {
        path: path.to_path_buf(),
        item: item.to_string(),
        reason,
    };
    let shape = ds.shape();
    if shape.len() != 2 {
        return Err(content(format!(
            "a {}-D dataset of shape {shape:?}, expected a 2-D height map",
            shape.len()
        )));
    }
    let values = (shape[0] as u64).saturating_mul(shape[1] as u64);
    let what = format!("{} × {} values", shape[0], shape[1]);
    crate::limits::check_fits(&what, values, 8).map_err(|e| CompareError::Length {
        path: path.to_path_buf(),
        problem: format!("{item}: {e}"),
    })?;
    let stored_bytes = ds
        .dtype()
        .map(|t| t.size() as u64)
        .map_err(h5err(path, item))?;
    let need = values.saturating_mul(stored_bytes);
    if ds.filters().is_empty() && need > file_len {
        return Err(CompareError::Length {
            path: path.to_path_buf(),
            problem: format!(
                "{item}: its header gives {what} of {stored_bytes} bytes ({} B), more than the \
                 file's {file_len} bytes: not a whole height map",
                need
            ),
        });
    }
    Ok(())
}

/// Reads the surface of a `.datx` file as heights.
///
/// # Errors
/// [`CompareError::Content`] naming the group, dataset or attribute that is
/// missing or not what the layout above says; [`CompareError::Length`] for
/// a file that is not plain or a dataset larger than memory or the file.
pub fn read(path: &Path) -> Result<InterferometerMap, CompareError> {
    let meta = std::fs::metadata(path).map_err(|source| CompareError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !meta.is_file() {
        return Err(CompareError::Length {
            path: path.to_path_buf(),
            problem: "not a plain file (a device, a pipe or a folder): a .datx file is an HDF5 \
                      file of the size its datasets need"
                .into(),
        });
    }
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
    bounded(&ds, path, &item, meta.len())?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A `.datx` at `path` whose `/Data/Surface/S` has `shape`, its values
    /// `values` written (none: the dataset is created and left unwritten),
    /// chunked by `chunk` (none: contiguous), in nm.
    fn write(path: &Path, shape: (usize, usize), values: Option<&[f64]>, chunk: Option<usize>) {
        let f = hdf5::File::create(path).unwrap();
        let g = f
            .create_group("Data")
            .unwrap()
            .create_group("Surface")
            .unwrap();
        let b = g.new_dataset::<f64>().shape(shape);
        let ds = match chunk {
            Some(c) => b.chunk((c, c)).create("S"),
            None => b.create("S"),
        }
        .unwrap();
        if let Some(v) = values {
            ds.write_raw(v).unwrap();
        }
        ds.new_attr::<VarLenUnicode>()
            .create("Unit")
            .unwrap()
            .write_scalar(&"nm".parse::<VarLenUnicode>().unwrap())
            .unwrap();
    }

    #[test]
    fn a_whole_map_reads() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.datx");
        let v: Vec<f64> = (0..12).map(f64::from).collect();
        write(&p, (3, 4), Some(&v), None);
        let m = read(&p).unwrap();
        assert_eq!((m.height, m.width), (3, 4));
        assert_eq!(m.heights_nm, v);
    }

    #[test]
    fn headers_larger_than_memory_or_the_file_and_devices_are_refused_first() {
        let dir = tempfile::tempdir().unwrap();
        // 200 000² f64 = 320 GB claimed by a file of a few kB (chunked, no
        // chunk written: HDF5 would answer with fill values).
        let huge = dir.path().join("huge.datx");
        write(&huge, (200_000, 200_000), None, Some(64));
        assert!(std::fs::metadata(&huge).unwrap().len() < 1 << 20);
        let e = read(&huge).unwrap_err().to_string();
        assert!(
            e.contains("200000 × 200000 values") && e.contains("of memory"),
            "{e}"
        );
        // 2000² f64 = 32 MB, unfiltered, never written: the file cannot hold it.
        let empty = dir.path().join("empty.datx");
        write(&empty, (2000, 2000), None, None);
        let e = read(&empty).unwrap_err().to_string();
        assert!(
            e.contains("32000000 B") && e.contains("more than the file's"),
            "{e}"
        );
        // A link to /dev/zero is refused before HDF5 reads a byte of it.
        let zero = dir.path().join("zero.datx");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        let e = read(&zero).unwrap_err().to_string();
        assert!(e.contains("not a plain file"), "{e}");
    }
}
