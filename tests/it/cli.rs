//! The `mfd` binary as an operator runs it: files appear where it says, and
//! bad input ends with one clear line naming the file and field.

use crate::common;

use crate::common::mfd;

#[test]
fn simulate_then_trace_on_the_fixture_station() {
    let dir = tempfile::tempdir().unwrap();
    let station = common::public_small().join("station.toml");
    let acq = dir.path().join("acq");
    let out = mfd(&[
        "simulate",
        "--station",
        station.to_str().unwrap(),
        "--random-surfaces",
        "5",
        "--tau-start",
        "1",
        "--tau-stop",
        "20",
        "--tau-step",
        "1",
        "--noise",
        "0.02",
        "--png",
        "--out",
        acq.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("simulated 40 frames of 48x48"));
    assert!(acq.join("frames/000039.png").is_file());
    let trace = dir.path().join("trace");
    let truth = acq.join("truth/truth_surfaces.json");
    let out = mfd(&[
        "trace",
        "--station",
        station.to_str().unwrap(),
        "--surfaces",
        truth.to_str().unwrap(),
        "--out",
        trace.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The simulator's truth and `mfd trace` are the same forward model: bit-identical.
    let a = std::fs::read(trace.join("screen_coords.npy")).unwrap();
    let b = std::fs::read(acq.join("truth/truth_screen_coords.npy")).unwrap();
    assert_eq!(a, b);
    // A second simulate into the same folder refuses without --overwrite.
    let out = mfd(&[
        "simulate",
        "--station",
        station.to_str().unwrap(),
        "--out",
        acq.to_str().unwrap(),
        "--tau-stop",
        "2",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--overwrite"));
}

#[test]
fn bad_station_names_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(common::repo("calib/paper-sim.toml")).unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        text.replace("thickness_mm = 10.0", "thickness_mm = 0.0"),
    )
    .unwrap();
    let out = mfd(&[
        "trace",
        "--station",
        bad.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    // 3: an input file that is not valid (src/cli/exit.rs).
    assert_eq!(out.status.code(), Some(3));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.toml") && err.contains("element.thickness_mm"),
        "{err}"
    );
}
