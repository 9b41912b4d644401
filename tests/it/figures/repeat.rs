//! `mfd measure --repeat 6` on the simulated camera: the spread of each
//! surface over the runs against the error each run reported.

use crate::common;

/// Six measurements of the fixture's true surfaces (400 patterns, 2 %
/// noise, 36 terms fixed so that every run fits the same model): each
/// surface's spread over the runs over its reported expected error is in
/// 0.5–2 (the criterion: with 6 runs the RMS departure of ~33
/// coefficients is known to about 1/√(2·5·33) ≈ 5 %, so a right σ lands
/// near 1 and a σ wrong by 2× outside).
#[test]
fn six_repeated_measurements_spread_as_reported() {
    let dir = tempfile::tempdir().unwrap();
    let station = common::public_small().join("station.toml");
    let truth = common::public_small().join("truth/truth_surfaces.json");
    let out = dir.path().display().to_string();
    let log = common::mfd_ok(&[
        "measure",
        "--station",
        station.to_str().unwrap(),
        "--sim-surfaces",
        truth.to_str().unwrap(),
        "--out",
        &out,
        "--tau-start",
        "0.5",
        "--tau-stop",
        "100",
        "--tau-step",
        "0.5",
        "--noise",
        "0.02",
        "--terms",
        "36",
        "--repeat",
        "6",
    ]);
    assert!(log.contains("run 6 of 6"), "{log}");
    let text = std::fs::read_to_string(dir.path().join("repeatability.json")).unwrap();
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(r["runs"], 6);
    for name in ["front", "back"] {
        let ratio = r[name]["spread_over_reported"].as_f64().unwrap();
        println!("{name}: spread over reported {ratio:.3}");
        assert!((0.5..=2.0).contains(&ratio), "{name}: {ratio}\n{log}");
    }
    assert!(
        r["figures"]["plate.wedge_arcsec"]["ratio"]
            .as_f64()
            .is_some(),
        "{text}"
    );
    for k in 1..=6 {
        assert!(dir
            .path()
            .join(format!("run-{k}/result/summary.json"))
            .is_file());
    }
    let html = std::fs::read_to_string(dir.path().join("run-6/result/report.html")).unwrap();
    assert!(html.contains("Repeatability over 6 runs"));
    // The result block: the figures, the ISO notation, the plate's maps.
    for text in [
        "<h2>Result</h2>",
        "ISO 10110-5",
        "λ = 546.07 nm",
        "thickness variation (nm, axes mm)",
        "transmitted wavefront (nm, axes mm)",
    ] {
        assert!(html.contains(text), "{text}");
    }
    // compare --surfaces prints the figures against the truth's.
    let run = dir.path().join("run-1/result");
    let log = common::mfd_ok(&[
        "compare",
        "--surfaces",
        run.join("surfaces.json").to_str().unwrap(),
        "--truth-surfaces",
        truth.to_str().unwrap(),
        "--summary",
        run.join("summary.json").to_str().unwrap(),
    ]);
    assert!(log.contains("figures against the truth"), "{log}");
    assert!(log.contains("17 figures: RMS z"), "{log}");
}
