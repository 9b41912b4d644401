//! The calibration from the command line, as an operator runs it on a
//! simulated session: `mfd calibrate simulate` (targets, flat points, a
//! 32-frame phase-shifting acquisition of the reference flat at gamma 2),
//! `check`, `solve`; the calibrated station's flat-reflected screen points
//! against the truth's; a plate measured on the truth and reconstructed
//! with `--uncertainty`; and a flat acquisition that is not of a flat.

use crate::common;

use std::path::Path;

use mfd::calibrate::simulate::flat_truth;
use mfd::optics::station::{Station, StationUncertainty};

fn simulated_session(dir: &Path) -> String {
    let s = dir.join("session");
    // Binned 4 × 4 (324 × 241 pixels, the paper's field of view): the
    // whole chain in seconds.
    common::mfd_ok(&[
        "calibrate",
        "simulate",
        "--out",
        s.to_str().unwrap(),
        "--bin",
        "4",
        "--seed",
        "3",
    ]);
    s.to_str().unwrap().to_string()
}

#[test]
fn a_simulated_session_calibrates_and_measures_within_its_uncertainty() {
    let dir = tempfile::tempdir().unwrap();
    let session = simulated_session(dir.path());
    assert!(common::mfd_ok(&["calibrate", "check", &session]).contains("ready to solve"));
    let cal = dir.path().join("cal");
    let printed = common::mfd_ok(&[
        "calibrate",
        "solve",
        &session,
        "--out",
        cal.to_str().unwrap(),
        "--display-gamma",
        "2",
    ]);
    println!("{printed}");
    for picture in ["targets.png", "flat_residuals.png"] {
        let file = std::io::BufReader::new(std::fs::File::open(cal.join(picture)).unwrap());
        let info = png::Decoder::new(file).read_info().unwrap();
        assert!(info.info().width >= 400, "{picture}");
    }
    let station = Station::load(&cal.join("station.toml")).unwrap();
    assert!(station.needs_version_2());
    let unc = StationUncertainty::load(&cal.join("station_uncertainty.toml")).unwrap();
    assert!(unc.names.len() >= 20, "{:?}", unc.names);
    let truth = Station::load(&Path::new(&session).join("truth/station.toml")).unwrap();
    // The issue: flat-reflected screen points within 0.05 screen px of the
    // truth, over the sensor where the rays meet the Ø 150 mm flat.
    // Beyond the flat (the sensor's rim) it is printed, not asserted: this
    // sensor's pixels are 4 × the paper's, its centroids 4 × coarser in
    // angle (tests/it/calibrate_adjust.rs bounds the full sensor's rim).
    let (mut worst, mut worst_rim) = (0.0_f64, 0.0_f64);
    for j in (0..truth.camera.height).step_by(4) {
        for i in (0..truth.camera.width).step_by(4) {
            let (Some((t, hit)), Some((c, _))) =
                (flat_truth(&truth, i, j), flat_truth(&station, i, j))
            else {
                continue;
            };
            if hit.x.hypot(hit.y) <= 75.0 {
                worst = worst.max((t - c).norm());
            } else {
                worst_rim = worst_rim.max((t - c).norm());
            }
        }
    }
    println!(
        "flat-reflected screen points: worst {worst:.4} screen px from the truth on the flat, \
         {worst_rim:.4} beyond it"
    );
    assert!(worst <= 0.05, "worst {worst} px");

    // A plate on the truth (5 % noise), reconstructed on the calibration.
    let acq = dir.path().join("plate");
    let truth_station = format!("{session}/truth/station.toml");
    common::mfd_ok(&[
        "simulate",
        "--station",
        &truth_station,
        "--random-surfaces",
        "5",
        "--noise",
        "0.05",
        "--out",
        acq.to_str().unwrap(),
    ]);
    let rec = dir.path().join("rec");
    let printed = common::mfd_ok(&[
        "reconstruct",
        acq.to_str().unwrap(),
        "--station",
        cal.join("station.toml").to_str().unwrap(),
        "--uncertainty",
        cal.join("station_uncertainty.toml").to_str().unwrap(),
        "--out",
        rec.to_str().unwrap(),
    ]);
    assert!(printed.contains("= noise"), "{printed}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rec.join("summary.json")).unwrap()).unwrap();
    let cmp = common::mfd_ok(&[
        "compare",
        "--surfaces",
        rec.join("surfaces.json").to_str().unwrap(),
        "--truth-surfaces",
        acq.join("truth/truth_surfaces.json").to_str().unwrap(),
    ]);
    for (k, side) in ["front", "back"].iter().enumerate() {
        let total = summary["station"][side]["total_rms_nm"].as_f64().unwrap();
        let line = cmp
            .lines()
            .filter(|l| l.contains("RMS error"))
            .nth(k)
            .unwrap();
        let err: f64 = line
            .split("RMS error ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        println!("{side}: error {err:.2} nm against {total:.2} nm reported (noise and station)");
        // The issue: within 2× the reported uncertainty, and 10 nm RMS.
        assert!(
            err <= 2.0 * total && err <= 10.0,
            "{side}: {err} nm vs {total} nm"
        );
    }
}

#[test]
fn a_reference_flat_with_two_reflections_is_refused_naming_the_entry() {
    let dir = tempfile::tempdir().unwrap();
    let session = simulated_session(dir.path());
    // Record the element (two reflections) where the flat should be.
    let flat = Path::new(&session).join("flat");
    std::fs::remove_dir_all(&flat).unwrap();
    let truth_station = format!("{session}/truth/station.toml");
    common::mfd_ok(&[
        "simulate",
        "--station",
        &truth_station,
        "--out",
        flat.to_str().unwrap(),
    ]);
    let cal = dir.path().join("cal");
    let out = common::mfd(&[
        "calibrate",
        "solve",
        &session,
        "--out",
        cal.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("reference_flat.acquisition") && err.contains("two reflections"),
        "{err}"
    );
}
