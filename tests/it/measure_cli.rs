//! `mfd measure` on the simulated station: a whole run, the streamed
//! reconstruction against `mfd reconstruct` on the recorded folder, a
//! disconnect and its resume, Ctrl-C, and backends not built.

use crate::common;
use crate::common::output_text as text;

use std::path::Path;

use crate::common::mfd;
use mfd::acquire::acquisition::Acquisition;

fn station() -> String {
    common::public_small()
        .join("station.toml")
        .display()
        .to_string()
}

/// `mfd measure` on the fixture station with a 2 × 30-pattern schedule
/// (the default camera `sim`, display `offscreen`): τ 1…30 in steps of 1,
/// unambiguous over the whole screen (a step of 2 repeats every point half
/// a screen away, and the fits came back on those aliases, 1 300 px from
/// the truth — which the station check now reports).
fn measure(out: &Path, extra: &[&str]) -> std::process::Output {
    let st = station();
    let out = out.display().to_string();
    let mut args = vec![
        "measure",
        "--station",
        &st,
        "--out",
        &out,
        "--tau-start",
        "1",
        "--tau-stop",
        "30",
        "--tau-step",
        "1",
        "--noise",
        "0.001",
    ];
    args.extend_from_slice(extra);
    mfd(&args)
}

#[test]
fn measure_records_and_reconstructs_like_reconstruct() {
    let dir = tempfile::tempdir().unwrap();
    let out = measure(dir.path(), &["--sim-drop-every", "7"]);
    let log = text(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("captured 60 frames"), "{log}");
    // 60 patterns, every 7th exposure lost: 9 re-shoots (see measure_sim).
    assert!(log.contains("re-shoots 9 (timeouts 9"), "{log}");
    let acq = Acquisition::open(&dir.path().join("acquisition")).unwrap();
    assert_eq!((acq.frames().len(), acq.complete_frames()), (60, 60));
    let streamed = std::fs::read(dir.path().join("result/screen_coords.npy")).unwrap();

    // The same stages from disk give the same maps, byte for byte.
    let again = dir.path().join("again");
    let acq_dir = dir.path().join("acquisition").display().to_string();
    let out = mfd(&[
        "reconstruct",
        &acq_dir,
        "--out",
        &again.display().to_string(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let from_disk = std::fs::read(again.join("screen_coords.npy")).unwrap();
    assert!(streamed == from_disk, "streamed and re-read maps differ");
}

#[test]
fn a_disconnect_is_reported_and_resume_completes_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = measure(
        dir.path(),
        &["--sim-disconnect-after", "17", "--no-reconstruct"],
    );
    let log = text(&out);
    assert!(!out.status.success(), "{log}");
    assert!(
        log.contains("frame 17") && log.contains("disconnected") && log.contains("17 of 60 frames"),
        "{log}"
    );
    let acq = Acquisition::open(&dir.path().join("acquisition")).unwrap();
    assert_eq!((acq.frames().len(), acq.complete_frames()), (17, 17));

    let out = measure(dir.path(), &["--resume"]);
    let log = text(&out);
    assert!(out.status.success(), "{log}");
    assert!(
        log.contains("captured 43 frames") && log.contains("60 of 60 recorded"),
        "{log}"
    );
    assert!(dir.path().join("result/screen_coords.npy").is_file());
}

#[test]
fn an_existing_acquisition_is_not_replaced_without_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    assert!(measure(dir.path(), &["--no-reconstruct"]).status.success());
    let out = measure(dir.path(), &["--no-reconstruct"]);
    assert!(!out.status.success());
    assert!(text(&out).contains("--overwrite"), "{}", text(&out));
}

#[test]
fn ctrl_c_stops_cleanly_with_a_readable_partial_acquisition() {
    let dir = tempfile::tempdir().unwrap();
    let st = station();
    let out = dir.path().display().to_string();
    // 200 patterns at ≥ 20 ms each: still running when the signal comes.
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_mfd"))
        .args([
            "measure",
            "--station",
            &st,
            "--out",
            &out,
            "--tau-start",
            "1",
            "--tau-stop",
            "100",
            "--tau-step",
            "1",
            "--settle-ms",
            "20",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let manifest = dir.path().join("acquisition/acquisition.toml");
    // Wait until frames are being recorded, then interrupt.
    let t0 = std::time::Instant::now();
    while Acquisition::open(&manifest).is_err() && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let status = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let output = child.wait_with_output().unwrap();
    let log = text(&output);
    // Interrupted is not success: the shell's 128 + SIGINT.
    assert_eq!(output.status.code(), Some(130), "{log}");
    assert!(
        log.contains("stopped after") && log.contains("--resume"),
        "{log}"
    );
    let acq = Acquisition::open(&manifest).unwrap();
    let n = acq.frames().len();
    assert!(n > 0 && n < 200, "{n}");
    assert_eq!(acq.complete_frames(), n);
    // And it resumes.
    let more = std::process::Command::new(env!("CARGO_BIN_EXE_mfd"))
        .args([
            "measure",
            "--station",
            &st,
            "--out",
            &out,
            "--tau-start",
            "1",
            "--tau-stop",
            "100",
            "--tau-step",
            "1",
            "--no-reconstruct",
            "--resume",
        ])
        .output()
        .unwrap();
    assert!(more.status.success(), "{}", text(&more));
    assert!(
        text(&more).contains("200 of 200 recorded"),
        "{}",
        text(&more)
    );
}

#[test]
fn exit_statuses_tell_bad_input_from_a_device_fault() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().display().to_string();
    let run = mfd(&[
        "measure",
        "--station",
        "/nonexistent/station.toml",
        "--out",
        &out,
    ]);
    assert_eq!(run.status.code(), Some(3), "{}", text(&run));
    assert!(
        text(&run).contains("/nonexistent/station.toml"),
        "{}",
        text(&run)
    );
    // A camera that disconnects is a device fault.
    let run = measure(
        dir.path(),
        &["--sim-disconnect-after", "3", "--no-reconstruct"],
    );
    assert_eq!(run.status.code(), Some(6), "{}", text(&run));
    // A backend not built in is an input (the option names it).
    let run = measure(dir.path(), &["--display", "HDMI-1", "--overwrite"]);
    assert_eq!(run.status.code(), Some(3), "{}", text(&run));
}

#[test]
fn a_successful_run_prints_no_error() {
    // Mesa and libwayland complain about a missing XDG_RUNTIME_DIR.
    let dir = tempfile::tempdir().unwrap();
    let st = station();
    let out = dir.path().display().to_string();
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_mfd"))
        .args([
            "measure",
            "--station",
            &st,
            "--out",
            &out,
            "--tau-start",
            "2",
            "--tau-stop",
            "10",
            "--tau-step",
            "2",
            "--no-reconstruct",
        ])
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let log = text(&run);
    assert!(run.status.success(), "{log}");
    assert!(!log.contains("error"), "{log}");
}

#[test]
fn backends_not_built_name_their_feature() {
    let dir = tempfile::tempdir().unwrap();
    if !cfg!(feature = "v4l") {
        let out = measure(dir.path(), &["--camera", "v4l:/dev/video0"]);
        assert!(!out.status.success());
        assert!(text(&out).contains("--features v4l"), "{}", text(&out));
    }
    let out = measure(dir.path(), &["--display", "HDMI-1"]);
    assert!(!out.status.success());
    assert!(text(&out).contains("--features display"), "{}", text(&out));
    let out = measure(dir.path(), &["--camera", "usb:0"]);
    assert!(text(&out).contains("expected `sim`"), "{}", text(&out));
}
