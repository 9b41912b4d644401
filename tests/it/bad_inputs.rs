//! Inputs that used to mix silently into a result (issue 37): a frame of
//! another bit depth or size among an acquisition's frames, one frame file
//! named by two `[[frame]]` tables, and a calibration session entry given
//! twice. Each is refused where it is read, with an error that names both
//! entries and exit status 3 (bad input).

use std::path::{Path, PathBuf};

use crate::common::{self, mfd};

use mfd::acquire::acquisition::{Acquisition, AcquisitionWriter, FrameImage, FrameInfo};
use mfd::calibrate::session_file::SessionFile;
use mfd::formats::image_io;

/// A copy of the independent fixture (48x48 16-bit PNGs) in a fresh folder.
fn fixture_copy() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("acq");
    std::fs::create_dir_all(dir.join("frames")).unwrap();
    let src = common::public_small();
    for name in ["acquisition.toml", "station.toml"] {
        std::fs::copy(src.join(name), dir.join(name)).unwrap();
    }
    for entry in std::fs::read_dir(src.join("frames")).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.join("frames").join(entry.file_name())).unwrap();
    }
    (tmp, dir)
}

/// Rewrites frame `k` of the copy as an 8-bit PNG of `w x h` holding its
/// counts scaled into 8 bits (what a camera in another mode would give).
fn replace_frame(dir: &Path, k: usize, w: u32, h: u32, bits: u8) {
    let path = dir.join(format!("frames/{k:06}.png"));
    let img = image_io::read_gray(&path).unwrap();
    let data: Vec<u16> = (0..(w * h) as usize)
        .map(|p| img.data[p % img.data.len()] >> (16 - bits))
        .collect();
    image_io::write_png(&path, w, h, bits, &data).unwrap();
}

fn status_and_text(args: &[&str]) -> (Option<i32>, String) {
    let out = mfd(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code(), text)
}

#[test]
fn an_8_bit_frame_among_16_bit_ones_is_refused_naming_both_files() {
    let (tmp, dir) = fixture_copy();
    replace_frame(&dir, 17, 48, 48, 8);
    let out = tmp.path().join("out");
    let (code, text) = status_and_text(&[
        "reconstruct",
        dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(3), "{text}");
    for needle in ["000017.png", "000000.png", "at 8 bits", "at 16 bits"] {
        assert!(text.contains(needle), "no {needle:?} in: {text}");
    }
    assert!(
        !out.join("surfaces.json").exists(),
        "a result was written: {text}"
    );
}

#[test]
fn a_frame_of_another_size_is_refused_in_any_reading_order() {
    let (_tmp, dir) = fixture_copy();
    replace_frame(&dir, 5, 40, 48, 16);
    let acq = Acquisition::open(&dir).unwrap();
    let mut f = Vec::new();
    // Frame 5 read before frame 0: the reference is still frame 0's header.
    let err = acq.read_frame(5, &mut f).unwrap_err().to_string();
    assert!(
        err.contains("000005.png") && err.contains("40x48") && err.contains("000000.png"),
        "{err}"
    );
    assert!(err.contains("48x48 pixels at 16 bits"), "{err}");
    acq.read_frame(6, &mut f).unwrap();
}

#[test]
fn the_same_file_twice_is_refused_naming_both_entries() {
    let (tmp, dir) = fixture_copy();
    let manifest = dir.join("acquisition.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    // Frame 9 names frame 3's file in another spelling.
    let text = text.replace(
        "file = \"frames/000009.png\"",
        "file = \"./frames/../frames/000003.png\"",
    );
    std::fs::write(&manifest, text).unwrap();
    let out = tmp.path().join("out");
    let (code, text) = status_and_text(&[
        "reconstruct",
        dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(3), "{text}");
    for needle in ["frame[9].file", "frame[3]", "000003.png"] {
        assert!(text.contains(needle), "no {needle:?} in: {text}");
    }
}

#[cfg(unix)]
#[test]
fn a_link_to_another_frame_is_the_same_file() {
    let (_tmp, dir) = fixture_copy();
    let link = dir.join("frames/000009.png");
    std::fs::remove_file(&link).unwrap();
    std::os::unix::fs::symlink(dir.join("frames/000002.png"), &link).unwrap();
    let err = Acquisition::open(&dir).unwrap_err().to_string();
    assert!(
        err.contains("frame[9].file") && err.contains("frame[2]"),
        "{err}"
    );
}

#[test]
fn a_repeated_pattern_with_its_own_file_stays_valid() {
    let (_tmp, dir) = fixture_copy();
    let manifest = dir.join("acquisition.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    // Frame 1 shows frame 0's pattern again: a second capture, own file.
    let text = text.replacen("tau = 1.0\n", "tau = 0.5\n", 1);
    std::fs::write(&manifest, text).unwrap();
    let acq = Acquisition::open(&dir).unwrap();
    assert_eq!(acq.frames()[0].tau, acq.frames()[1].tau);
}

#[test]
fn a_resumed_recording_keeps_its_bit_depth() {
    let tmp = tempfile::tempdir().unwrap();
    let schedule: Vec<FrameInfo> = (0..3)
        .map(|index| FrameInfo {
            index,
            direction_deg: 45.0,
            tau: 1.0 + index as f64,
            phase_rad: 0.0,
        })
        .collect();
    let data = vec![1000u16; 4 * 2];
    let frame = |bit_depth| FrameImage {
        width: 4,
        height: 2,
        bit_depth,
        data: &data,
    };
    let station = ("station.toml", String::new());
    let mut w = AcquisitionWriter::append(tmp.path(), station, &schedule, false).unwrap();
    w.write_frame(0, &frame(12)).unwrap();
    w.finish().unwrap();
    let mut w = AcquisitionWriter::resume(tmp.path(), &schedule).unwrap();
    let err = w.write_frame(1, &frame(8)).unwrap_err().to_string();
    assert!(
        err.contains("frame 1") && err.contains("16-bit") && err.contains("8-bit"),
        "{err}"
    );
    w.write_frame(1, &frame(12)).unwrap();
}

/// A simulated session (binned 4 × 4: seconds) whose `session.toml` is
/// rewritten by `edit`.
fn session_with(dir: &Path, edit: impl FnOnce(&mut SessionFile)) -> String {
    let s = dir.join("session");
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
    let path = s.join("session.toml");
    let mut file: SessionFile = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut file);
    std::fs::write(&path, toml::to_string(&file).unwrap()).unwrap();
    s.to_str().unwrap().to_string()
}

/// `calibrate check` names both entries and is not ready; `calibrate
/// solve` refuses with status 3 and writes nothing.
fn check_and_solve_refuse(session: &str, needles: &[&str]) {
    let (_, check) = status_and_text(&["calibrate", "check", session]);
    assert!(!check.contains("ready to solve"), "{check}");
    let out = Path::new(session).with_file_name("cal");
    let (code, solve) = status_and_text(&[
        "calibrate",
        "solve",
        session,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(3), "{solve}");
    for n in needles {
        assert!(check.contains(n), "check: no {n:?} in:\n{check}");
        assert!(solve.contains(n), "solve: no {n:?} in:\n{solve}");
    }
    assert!(!out.join("station.toml").exists());
}

#[test]
fn a_target_position_given_twice_is_refused_naming_both_entries() {
    let tmp = tempfile::tempdir().unwrap();
    let session = session_with(tmp.path(), |f| {
        // Target 4 at target 1's reading, with its own frame (centroid).
        f.target_point[4].stage_mm = f.target_point[1].stage_mm;
    });
    check_and_solve_refuse(
        &session,
        &["target_point[4].stage_mm", "target_point[1].stage_mm"],
    );
}

#[test]
fn a_target_frame_named_twice_is_refused_naming_both_entries() {
    let tmp = tempfile::tempdir().unwrap();
    let session = session_with(tmp.path(), |f| {
        let first = f.target_point[0]
            .image
            .clone()
            .expect("simulated targets have frames");
        f.target_point[5].image = Some(format!("./{first}"));
        f.target_point[5].image_px = None;
    });
    check_and_solve_refuse(
        &session,
        &["target_point[5].image", "target_point[0].image"],
    );
}

#[test]
fn a_flat_reading_copied_is_refused_naming_both_entries() {
    let tmp = tempfile::tempdir().unwrap();
    let mut last = 0;
    let session = session_with(tmp.path(), |f| {
        let copy = f.flat_point[0].clone();
        f.flat_point.push(copy);
        last = f.flat_point.len() - 1;
    });
    let repeat = format!("flat_point[{last}].stage_mm");
    check_and_solve_refuse(&session, &[&repeat, "flat_point[0].stage_mm"]);
}
