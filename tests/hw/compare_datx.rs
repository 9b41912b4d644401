//! Zygo `.datx` (feature `datx`): a file written by h5py (python3) in the
//! layout `mfd::compare::datx` documents — `/Data/Surface/<name>` with
//! `Unit`, `Wavelength`, `Interferometric Scale Factor`, `Obliquity
//! Factor`, `Lateral Resolution` and `No Data` — of mfd's surface plus a
//! known term must give that term back to 0.1 nm (the issue's figure; the
//! map is stored as float64 fringes, so nothing but the fit's rounding
//! limits it).
#![cfg(feature = "datx")]

use crate::compare_support::*;
use mfd::compare::{self, LoadOptions, RegistrationOptions};
use mfd::formats::surfaces_file::SurfacesFile;

const WRITER: &str = r#"
import sys, numpy as np, h5py
raw, out, w, h, no_data = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
wl, s, o = 632.8e-9, 0.5, 1.0
nm = np.fromfile(raw, dtype='<f8').reshape(h, w)
fringes = nm * 1e-9 / (wl * s * o)
fringes[np.isnan(fringes)] = no_data
with h5py.File(out, 'w') as f:
    d = f.create_group('Data').create_group('Surface').create_dataset('{6C9A5A9E}', data=fringes)
    d.attrs['Unit'] = 'Fringes'
    d.attrs['Wavelength'] = wl
    d.attrs['Interferometric Scale Factor'] = s
    d.attrs['Obliquity Factor'] = o
    d.attrs['Lateral Resolution'] = 0.3e-3
    d.attrs['No Data'] = no_data
"#;

/// Debian's python3 (where `scripts/install-deps.sh` installs h5py and
/// numpy), before any other python3 on the PATH.
fn python() -> &'static str {
    if std::path::Path::new("/usr/bin/python3").is_file() {
        "/usr/bin/python3"
    } else {
        "python3"
    }
}

fn write_datx(dir: &std::path::Path, p: &Placement, nm: &[f64]) -> std::path::PathBuf {
    let raw = dir.join("map.f64");
    let bytes: Vec<u8> = nm.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&raw, bytes).unwrap();
    let script = dir.join("write_datx.py");
    std::fs::write(&script, WRITER).unwrap();
    let out = dir.join("flat.datx");
    let status = std::process::Command::new(python())
        .arg(&script)
        .arg(&raw)
        .arg(&out)
        .arg(p.width.to_string())
        .arg(p.height.to_string())
        .arg("1.7976931348623157e308")
        .status()
        .unwrap();
    assert!(status.success(), "h5py writer failed");
    out
}

#[test]
fn datx_written_by_h5py_gives_back_the_added_term() {
    let dir = tempfile::tempdir().unwrap();
    let surfaces = write_surfaces(dir.path());
    let p = Placement::centred(-40.0, false);
    let path = write_datx(dir.path(), &p, &map(&p, 7, 5.0));
    let m = compare::load(&path, &LoadOptions::default()).unwrap();
    assert_eq!(m.format, "Zygo .datx");
    assert!((m.pixel_mm.unwrap() - 0.3).abs() < 1e-12);
    assert!((m.wavelength_nm.unwrap() - 632.8).abs() < 1e-9);
    let s = SurfacesFile::load(&surfaces).unwrap();
    let opts = RegistrationOptions {
        rotation_deg: Some(-40.0),
        flip: Some(false),
        ..RegistrationOptions::default()
    };
    let c = compare::compare(&m, &s, &surfaces, "front", &opts).unwrap();
    for t in &c.terms {
        let want = if t.noll == 7 { -5.0 } else { 0.0 };
        assert!(
            (t.difference_nm - want).abs() < 0.1,
            "j = {}: {}",
            t.noll,
            t.difference_nm
        );
    }
    println!(
        "datx: difference RMS {:.4} nm, j = 7 difference {:.4} nm",
        c.difference_rms_nm, c.terms[6].difference_nm
    );
    assert!(
        (c.difference_rms_nm - 5.0).abs() < 0.1,
        "{}",
        c.difference_rms_nm
    );
}

#[test]
fn datx_without_the_surface_group_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("w.py");
    std::fs::write(
        &script,
        "import sys, h5py\nwith h5py.File(sys.argv[1], 'w') as f:\n    f.create_group('Data')\n",
    )
    .unwrap();
    let path = dir.path().join("empty.datx");
    assert!(std::process::Command::new(python())
        .arg(&script)
        .arg(&path)
        .status()
        .unwrap()
        .success());
    let e = compare::load(&path, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("empty.datx") && e.contains("Data/Surface"),
        "{e}"
    );
}
