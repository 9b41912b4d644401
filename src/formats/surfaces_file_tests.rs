//! Unit tests of `surfaces_file`: the spec's version-1 example, bad fields named.

use super::*;

const GOOD: &str = r#"{"format": "mfd-surfaces/1",
    "zernike": {"ordering": "noll", "normalization": "rms", "radius_mm": 25.5, "center_mm": [0.0, 0.0]},
    "front": {"coefficients_nm": [0.0, 12.5, -3.1, 40.2]}, "back": null}"#;

fn load_text(text: &str) -> Result<SurfacesFile, SurfacesFileError> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("surfaces.json");
    std::fs::write(&p, text).unwrap();
    SurfacesFile::load(&p)
}

#[test]
fn spec_example_loads_and_round_trips() {
    let f = load_text(GOOD).unwrap();
    assert_eq!(f.front_coefficients().unwrap().len(), 4);
    assert!(f.back.is_none());
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.json");
    f.save(&p).unwrap();
    assert_eq!(SurfacesFile::load(&p).unwrap(), f);
}

#[test]
fn bad_files_name_the_field() {
    let err = load_text(&GOOD.replace("\"noll\"", "\"ansi\""))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("zernike.ordering") && err.contains("ansi"),
        "{err}"
    );
    let err = load_text(&GOOD.replace("\"back\": null", "\"back\": null, \"extra\": 1"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("extra"), "{err}");
    let err = load_text(&GOOD.replace("25.5", "-1"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("zernike.radius_mm"), "{err}");
}

/// More coefficients than any basis holds is an error where the file is
/// read, not later when the surface is built (issue 19).
#[test]
fn more_terms_than_a_basis_holds_are_refused() {
    let many = vec!["0.0"; MAX_TERMS + 1].join(", ");
    let text = GOOD.replace("[0.0, 12.5, -3.1, 40.2]", &format!("[{many}]"));
    let err = load_text(&text).unwrap_err().to_string();
    assert!(
        err.contains("front.coefficients_nm") && err.contains("5151"),
        "{err}"
    );
    let most = vec!["0.0"; MAX_TERMS].join(", ");
    let text = GOOD.replace("[0.0, 12.5, -3.1, 40.2]", &format!("[{most}]"));
    assert!(load_text(&text).is_ok());
}
