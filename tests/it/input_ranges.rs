//! Issue 19, case 3: numbers that enter from a file or an option, out of
//! the range the instrument can mean, are refused where they enter, naming
//! the file, the field, the value and the allowed range — before anything
//! of their size is allocated or computed.

use crate::common;

use std::path::{Path, PathBuf};

use mfd::acquire::acquisition::{check_against_station, Acquisition};
use mfd::optics::station::Station;
use mfd::pipeline::{reconstruct, Input, Options};

/// A copy of the fixture's manifest and station in a fresh folder, with
/// frame 3's τ (1-based line of the fixture: `tau = 2.0`) replaced by `tau`.
/// The frames are not copied: every check here must come before any frame
/// is read.
fn acquisition_with_tau(name: &str, tau: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mfd-input-ranges-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = common::public_small();
    let text = std::fs::read_to_string(src.join("acquisition.toml")).unwrap();
    let replaced = text.replacen("tau = 2.0\n", &format!("tau = {tau}\n"), 1);
    assert_ne!(replaced, text, "the fixture has a frame with tau = 2.0");
    std::fs::write(dir.join("acquisition.toml"), replaced).unwrap();
    std::fs::copy(src.join("station.toml"), dir.join("station.toml")).unwrap();
    dir
}

fn station() -> Station {
    Station::load(&common::public_small().join("station.toml")).unwrap()
}

/// τ = 1e300 panicked ("capacity overflow") in the periodogram, 1e9 aborted
/// out of memory, 1e4 ran for minutes, 1000 gave a confident wrong result:
/// all above what the fixture's 1600×1200 screen can show at 45°
/// (τ ≤ L/2 = 2800/√2/2 = 989.95), all refused before a frame is read.
#[test]
fn tau_beyond_the_screen_is_refused_before_reconstruction() {
    let station = station();
    for tau in ["1e300", "1e9", "1e4", "1000.0"] {
        let dir = acquisition_with_tau(&format!("tau{tau}"), tau);
        let mut acq = Acquisition::open(&dir).unwrap();
        let err = check_against_station(&acq, &station)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("acquisition.toml")
                && err.contains("frame[3].tau")
                && err.contains("989.95"),
            "{tau}: {err}"
        );
        let options = Options::default();
        let result = reconstruct(
            Input::Acquisition(&mut acq),
            &station,
            &options,
            &mut |_, _| {},
        );
        let Err(err) = result else {
            panic!("{tau}: reconstruct accepted the acquisition");
        };
        let err = err.to_string();
        assert!(err.contains("frame[3].tau"), "{tau}: {err}");
        std::fs::remove_dir_all(&dir).ok();
    }
    // The largest τ the screen shows is accepted.
    let dir = acquisition_with_tau("tau989", "989.9");
    let acq = Acquisition::open(&dir).unwrap();
    assert!(check_against_station(&acq, &station).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}

/// Non-finite and non-positive τ never get past the manifest reader.
#[test]
fn non_finite_or_non_positive_tau_is_refused_by_the_reader() {
    for tau in ["nan", "inf", "-inf", "0.0", "-0.0", "-2.0"] {
        let dir = acquisition_with_tau(&format!("bad{tau}"), tau);
        let err = Acquisition::open(&dir).unwrap_err().to_string();
        assert!(err.contains("frame[3].tau"), "{tau}: {err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}

fn station_text_with(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(common::public_small().join("station.toml")).unwrap();
    let replaced = text.replacen(from, to, 1);
    assert_ne!(replaced, text, "{from} is in the fixture station");
    replaced
}

/// A 4e9-pixel sensor panicked in the tracer: the station reader refuses
/// it, naming the field and the limit.
#[test]
fn sensor_and_screen_sizes_are_bounded() {
    let path = Path::new("station.toml");
    for (res, want) in [
        ("[65536, 65536]", "pixels a sensor can have"),
        ("[4000000000, 1]", "65536 px a sensor can have"),
    ] {
        let text = station_text_with("resolution = [48, 48]", &format!("resolution = {res}"));
        let err = Station::from_toml_str(&text, path).unwrap_err().to_string();
        assert!(
            err.contains("station.toml") && err.contains("camera.resolution") && err.contains(want),
            "{res}: {err}"
        );
    }
    let text = station_text_with("resolution = [1600, 1200]", "resolution = [100000, 1200]");
    let err = Station::from_toml_str(&text, path).unwrap_err().to_string();
    assert!(
        err.contains("screen.resolution") && err.contains("16384"),
        "{err}"
    );
    // The largest sensor accepted: 8192 × 8192 = 2^26 pixels (behind a
    // 60 mm lens: the fixture's 6 mm would see 84° to the corner, beyond
    // the 80° half field a station's camera may have).
    let text = station_text_with("resolution = [48, 48]", "resolution = [8192, 8192]").replacen(
        "focal_length_mm = 6.0",
        "focal_length_mm = 60.0",
        1,
    );
    assert!(Station::from_toml_str(&text, path).is_ok());
}

/// τ up to 1e9 in steps of 0.001 aborted out of memory in `mfd simulate`:
/// now an input error (exit 3) before the schedule is expanded.
#[test]
fn simulate_refuses_a_schedule_too_long_or_beyond_the_screen() {
    let station = common::public_small().join("station.toml");
    let out = std::env::temp_dir().join(format!("mfd-input-ranges-sim-{}", std::process::id()));
    let station = station.to_str().unwrap();
    let out_s = out.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["simulate", "--station", station, "--out", out_s];
        args.extend_from_slice(extra);
        common::mfd(&args)
    };
    let r = run(&["--tau-stop", "1e9", "--tau-step", "0.001"]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(3), "{err}");
    assert!(err.contains("tau-step") && err.contains("100000"), "{err}");

    let r = run(&["--tau-stop", "1000", "--tau-step", "1", "--tau-start", "1"]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(3), "{err}");
    assert!(err.contains("tau-stop") && err.contains("989.95"), "{err}");

    let schedule = out.with_extension("schedule.toml");
    std::fs::write(
        &schedule,
        "format = \"mfd-schedule/1\"\n[[frame]]\ndirection_deg = 0.0\ntau = 1.0\n\
         [[frame]]\ndirection_deg = 0.0\ntau = 801.0\n",
    )
    .unwrap();
    let r = run(&["--schedule", schedule.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(3), "{err}");
    assert!(
        err.contains("frame[1].tau") && err.contains("800.00"),
        "{err}"
    );
    assert!(!out.join("acquisition.toml").exists(), "nothing written");
    std::fs::remove_file(&schedule).ok();
    std::fs::remove_dir_all(&out).ok();
}

/// Hardware profiles (`hw/`): numbers a station is built from, checked
/// where they are read (a NaN settle time or gamma, a 64-bit ADC ran on).
#[test]
fn hardware_profiles_are_checked_where_read() {
    use mfd::optics::station::{CameraProfile, DisplayProfile};
    let dir = std::env::temp_dir().join(format!("mfd-input-ranges-hw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let display = std::fs::read_to_string(common::repo("hw/display/mtiph-e2m21gm.toml")).unwrap();
    let camera = std::fs::read_to_string(common::repo("hw/camera/baumer-txg12.toml")).unwrap();
    let path = dir.join("p.toml");
    for (from, to, field) in [
        ("gamma = 2.2", "gamma = nan", "gamma"),
        ("settle_ms = 30.0", "settle_ms = -1.0", "settle_ms"),
        ("diagonal_in = 21.3", "diagonal_in = 0.0", "diagonal_in"),
    ] {
        assert!(display.contains(from), "{from}");
        std::fs::write(&path, display.replacen(from, to, 1)).unwrap();
        let err = DisplayProfile::load(&path).unwrap_err().to_string();
        assert!(err.contains(field), "{to}: {err}");
    }
    for (from, to, field) in [
        ("bit_depth = 12", "bit_depth = 64", "bit_depth"),
        (
            "pixel_pitch_um = 3.75",
            "pixel_pitch_um = -3.75",
            "pixel_pitch_um",
        ),
    ] {
        assert!(camera.contains(from), "{from}");
        std::fs::write(&path, camera.replacen(from, to, 1)).unwrap();
        let err = CameraProfile::load(&path).unwrap_err().to_string();
        assert!(err.contains(field), "{to}: {err}");
    }
    std::fs::write(&path, &display).unwrap();
    assert!(DisplayProfile::load(&path).is_ok());
    std::fs::write(&path, &camera).unwrap();
    assert!(CameraProfile::load(&path).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}
