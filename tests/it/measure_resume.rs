//! `mfd measure --resume` appends only to an acquisition begun with the same
//! schedule, station, camera and settings (issue 19, case 2): a mismatch is
//! an input error (exit 3) that names each setting, held and given, and
//! appends nothing.

use crate::common;
use crate::common::output_text as text;

use std::path::Path;

use crate::common::mfd;
use mfd::acquire::acquisition::Acquisition;

/// `mfd measure` on `station` with a 2 × 30-pattern schedule, recording only.
fn measure(station: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let st = station.display().to_string();
    let out = out.display().to_string();
    let mut args = vec![
        "measure",
        "--station",
        &st,
        "--out",
        &out,
        "--tau-start",
        "2",
        "--tau-stop",
        "60",
        "--tau-step",
        "2",
        "--no-reconstruct",
    ];
    args.extend_from_slice(extra);
    mfd(&args)
}

/// SHA-256 of `bytes`, lower-case hex (sha2 directly, not mfd's helper).
fn sha256(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// A copy of the fixture station in `dir`, to be changed between runs.
fn station_copy(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("station.toml");
    std::fs::copy(common::public_small().join("station.toml"), &path).unwrap();
    path
}

/// Begins a 12-bit acquisition that the camera cuts off after 25 frames.
fn begin(station: &Path, out: &Path) {
    let run = measure(
        station,
        out,
        &["--bit-depth", "12", "--sim-disconnect-after", "25"],
    );
    assert!(!run.status.success(), "{}", text(&run));
    assert_eq!(recorded(out), 25);
}

fn recorded(out: &Path) -> usize {
    Acquisition::open(&out.join("acquisition"))
        .unwrap()
        .frames()
        .len()
}

/// Exit 3, the setting named with both values, how to start anew, and
/// nothing appended.
fn assert_refused(run: &std::process::Output, out: &Path, needles: &[&str]) {
    let log = text(run);
    assert_eq!(run.status.code(), Some(3), "{log}");
    for n in needles {
        assert!(log.contains(n), "missing {n:?} in: {log}");
    }
    assert!(
        log.contains("new --out folder") && log.contains("without --resume"),
        "{log}"
    );
    assert_eq!(recorded(out), 25, "frames were appended: {log}");
}

#[test]
fn resume_with_another_bit_depth_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let station = station_copy(dir.path());
    let out = dir.path().join("run");
    begin(&station, &out);
    let run = measure(&station, &out, &["--resume", "--bit-depth", "8"]);
    assert_refused(&run, &out, &["bit depth: held 12, given 8"]);
    // The same settings still resume, to the end.
    let run = measure(&station, &out, &["--resume", "--bit-depth", "12"]);
    assert!(run.status.success(), "{}", text(&run));
    assert!(text(&run).contains("60 of 60 recorded"), "{}", text(&run));
}

#[test]
fn resume_with_another_station_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let station = station_copy(dir.path());
    let out = dir.path().join("run");
    let held = std::fs::read(&station).unwrap();
    begin(&station, &out);
    let other = String::from_utf8(held.clone())
        .unwrap()
        .replace("refractive_index = 1.5", "refractive_index = 1.52");
    std::fs::write(&station, &other).unwrap();
    let run = measure(&station, &out, &["--resume", "--bit-depth", "12"]);
    let held_digest = sha256(&held);
    let given_digest = sha256(other.as_bytes());
    let expected =
        format!("station (SHA-256 of the file): held {held_digest}, given {given_digest}");
    assert_refused(&run, &out, &[&expected]);
}

#[test]
fn resume_with_a_longer_schedule_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let station = station_copy(dir.path());
    let out = dir.path().join("run");
    begin(&station, &out);
    // Its first 25 patterns are those recorded (direction by direction),
    // but it goes on with a third direction.
    let run = measure(
        &station,
        &out,
        &["--resume", "--bit-depth", "12", "--directions=45,-45,0"],
    );
    assert_refused(
        &run,
        &out,
        &["schedule: held 60 patterns", "given 90 patterns"],
    );
}
