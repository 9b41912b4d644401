//! `mfd report` on a small simulated measurement: a self-contained page
//! (nothing fetched, every image an inlined PNG that decodes) with every
//! section; with `--interferometer`, the comparison too.

use crate::common;

use crate::report_support::{check_self_contained, simulated_result};

#[test]
fn report_of_a_simulated_measurement_is_self_contained_and_complete() {
    let dir = tempfile::tempdir().unwrap();
    let result = simulated_result(dir.path());
    let out = common::mfd(&["report", result.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(result.join("report.html")).unwrap();
    let sizes = check_self_contained(&html);
    // front and back maps and charts, the breakdown, 5 quality maps.
    assert!(sizes.len() >= 10, "{} images", sizes.len());
    for section in [
        "What was measured",
        "Warnings",
        "Surfaces",
        "Uncertainty",
        "Surface fit",
        "Spectral stage",
        "Calibration",
    ] {
        assert!(
            html.contains(&format!("<h2>{section}")),
            "no section {section}"
        );
    }
    // What was measured: the acquisition beside the result and its station.
    assert!(html.contains("acquisition.toml") && html.contains("station.toml"));
    // No station uncertainty in the fixture: the page says σ are noise alone.
    assert!(html.contains("noise alone"));

    // The same surfaces as an "interferometer" map: a difference near 0.
    let s = mfd::formats::surfaces_file::SurfacesFile::load(&result.join("surfaces.json")).unwrap();
    let surface = mfd::formats::surfaces_file::to_surface(&s, s.front_coefficients()).unwrap();
    let (r, [cx, cy]) = (surface.basis().radius_mm(), surface.basis().center_mm());
    let n = 121;
    let p = 2.2 * r / n as f64;
    let map: Vec<f64> = (0..n * n)
        .map(|k| {
            let dx = ((k % n) as f64 + 0.5 - n as f64 / 2.0) * p;
            let dy = (n as f64 / 2.0 - (k / n) as f64 - 0.5) * p;
            surface.height_mm(cx + dx, cy + dy) * 1e6
        })
        .collect();
    let npy = dir.path().join("fizeau.npy");
    mfd::formats::npy::write_f64(&npy, &[n, n], &map).unwrap();
    let page = dir.path().join("with_fizeau.html");
    let out = common::mfd(&[
        "report",
        result.to_str().unwrap(),
        "--out",
        page.to_str().unwrap(),
        "--interferometer",
        npy.to_str().unwrap(),
        "--pixel-mm",
        &p.to_string(),
        "--rotation-deg",
        "0",
        "--flip",
        "false",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(&page).unwrap();
    let more = check_self_contained(&html);
    assert_eq!(
        more.len(),
        sizes.len() + 6,
        "3 maps and 3 coefficient charts more"
    );
    assert!(html.contains("Comparison with the interferometer"));
}

#[test]
fn a_folder_without_a_result_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = common::mfd(&["report", dir.path().to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(dir.path().to_str().unwrap()) && err.contains("surfaces.json"),
        "{err}"
    );
}

#[test]
fn measure_writes_the_report_with_the_calibration_beside_its_station() {
    let dir = tempfile::tempdir().unwrap();
    // A station with a calibration report beside it, as `mfd calibrate
    // solve` leaves one (`report.json`, calibrate::Report's fields).
    let cal = dir.path().join("cal");
    std::fs::create_dir_all(&cal).unwrap();
    std::fs::copy(
        common::public_small().join("station.toml"),
        cal.join("station.toml"),
    )
    .unwrap();
    let report = serde_json::json!({
        "steps": [{"name": "joint", "trials": 4, "chi2": 80.0, "dof": 78, "chi2_per_dof": 1.0256,
                   "selection": {}, "blocks": [{"name": "targets", "unit": "px", "count": 40,
                   "rms": 0.051, "expected_rms": 0.05, "chi2": 41.6}]}],
        "notes": ["the element's thickness as given"]
    });
    std::fs::write(cal.join("report.json"), report.to_string()).unwrap();
    let out = dir.path().join("m");
    let run = common::mfd(&[
        "measure",
        "--station",
        cal.join("station.toml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        // τ 1…30 step 1: unambiguous over the screen (step 2 puts every
        // fit on an alias half a screen away; tests/it/measure_cli.rs).
        "--tau-start",
        "1",
        "--tau-stop",
        "30",
        "--tau-step",
        "1",
        "--noise",
        "0.001",
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let page = out.join("result/report.html");
    assert!(
        stdout.contains(&format!("wrote the report {}", page.display())),
        "{stdout}"
    );
    let html = std::fs::read_to_string(&page).unwrap();
    check_self_contained(&html);
    // The acquisition beside the result was found, and through it the
    // station and its calibration.
    assert!(html.contains("60 (60 complete)"), "2 × 30 patterns");
    assert!(html.contains("1.0256") && html.contains("the element's thickness as given"));
}
