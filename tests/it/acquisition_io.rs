//! The acquisition reader and writer: the independent fixture reads, both
//! layouts round trip, and every kind of bad folder gives an error that
//! names the file, field or frame — while frames already on disk stay readable.

use crate::common;

use std::path::Path;

use mfd::acquire::acquisition::{
    Acquisition, AcquisitionWriter, FrameImage, FrameInfo, FrameLayout,
};
use mfd::formats::npy::StackDtype;

fn infos(n: usize) -> Vec<FrameInfo> {
    (0..n)
        .map(|index| FrameInfo {
            index,
            direction_deg: 45.0,
            tau: 0.5 * (index + 1) as f64,
            phase_rad: 0.0,
        })
        .collect()
}

fn frame(k: usize, w: usize, h: usize) -> Vec<u16> {
    (0..w * h)
        .map(|p| ((p * 31 + k * 1000) % 4096) as u16)
        .collect()
}

fn write(dir: &Path, layout: FrameLayout, n: usize, finish: bool) {
    let mut w =
        AcquisitionWriter::create(dir, "station.toml", layout, &infos(n), 5, 3, false).unwrap();
    let upto = if finish { n } else { n - 1 };
    for k in 0..upto {
        let data = frame(k, 5, 3);
        let image = FrameImage {
            width: 5,
            height: 3,
            bit_depth: 12,
            data: &data,
        };
        w.write_frame(k, &image).unwrap();
    }
    if finish {
        w.finish().unwrap();
    }
}

fn err_of(dir: &Path) -> String {
    Acquisition::open(dir).unwrap_err().to_string()
}

#[test]
fn reads_the_independent_fixture() {
    let mut acq = Acquisition::open(&common::public_small()).unwrap();
    assert_eq!(acq.frames().len(), 400);
    let (first, last) = (acq.frames()[0], acq.frames()[399]);
    assert_eq!((first.direction_deg, first.tau), (45.0, 0.5));
    assert_eq!((last.direction_deg, last.tau), (-45.0, 100.0));
    assert!(acq.station_path().ends_with("station.toml"));
    acq.check_resolution(48, 48).unwrap();
    let mut f = Vec::new();
    acq.read_frame(399, &mut f).unwrap();
    assert_eq!(f.len(), 48 * 48);
    acq.check_resolution(64, 48).unwrap();
    let err = acq.read_frame(0, &mut f).unwrap_err().to_string();
    assert!(
        err.contains("frame 0") && err.contains("000000.png") && err.contains("expected 64x48"),
        "{err}"
    );
}

#[test]
fn both_layouts_round_trip() {
    for layout in [
        FrameLayout::Stack {
            dtype: StackDtype::U16,
        },
        FrameLayout::Png { bit_depth: 16 },
    ] {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), layout, 4, true);
        let mut acq = Acquisition::open(dir.path()).unwrap();
        acq.check_resolution(5, 3).unwrap();
        let mut f = Vec::new();
        for k in 0..4 {
            acq.read_frame(k, &mut f).unwrap();
            assert_eq!(f, frame(k, 5, 3), "{layout:?} frame {k}");
        }
        assert_eq!(acq.frames()[3].tau, 2.0);
        // A second writer refuses to overwrite what is there.
        let again =
            AcquisitionWriter::create(dir.path(), "station.toml", layout, &infos(1), 5, 3, false);
        assert!(again.unwrap_err().to_string().contains("--overwrite"));
    }
}

#[test]
fn a_truncated_stack_keeps_its_frames_readable() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        FrameLayout::Stack {
            dtype: StackDtype::U16,
        },
        4,
        false,
    );
    let acq = Acquisition::open(dir.path()).unwrap();
    assert_eq!(acq.complete_frames(), 3);
    let mut f = Vec::new();
    for k in 0..3 {
        acq.read_frame(k, &mut f).unwrap();
        assert_eq!(f, frame(k, 5, 3));
    }
    let err = acq.read_frame(3, &mut f).unwrap_err().to_string();
    assert!(
        err.contains("frames.npy") && err.contains("3 complete frames of 4"),
        "{err}"
    );
}

#[test]
fn a_manifest_that_disagrees_with_the_stack_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        FrameLayout::Stack {
            dtype: StackDtype::U16,
        },
        4,
        true,
    );
    let m = dir.path().join("acquisition.toml");
    let text = std::fs::read_to_string(&m).unwrap();
    let cut = text.rfind("[[frame]]").unwrap();
    std::fs::write(&m, &text[..cut]).unwrap();
    let err = err_of(dir.path());
    assert!(
        err.contains("stack") && err.contains("holds 4 frames") && err.contains("lists 3"),
        "{err}"
    );
    let mut acq = Acquisition::open(&common::public_small()).unwrap();
    assert!(acq.check_resolution(48, 48).is_ok());
}

#[test]
fn a_frame_of_the_wrong_size_is_named() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), FrameLayout::Png { bit_depth: 16 }, 3, true);
    mfd::formats::image_io::write_png(&dir.path().join("frames/000001.png"), 4, 4, 16, &[0; 16])
        .unwrap();
    let mut acq = Acquisition::open(dir.path()).unwrap();
    acq.check_resolution(5, 3).unwrap();
    let mut f = Vec::new();
    acq.read_frame(0, &mut f).unwrap();
    let err = acq.read_frame(1, &mut f).unwrap_err().to_string();
    assert!(
        err.contains("frame 1") && err.contains("000001.png") && err.contains("4x4"),
        "{err}"
    );
    std::fs::remove_file(dir.path().join("frames/000002.png")).unwrap();
    let err = acq.read_frame(2, &mut f).unwrap_err().to_string();
    assert!(
        err.contains("frame 2") && err.contains("000002.png"),
        "{err}"
    );
}

#[test]
fn bad_manifests_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), FrameLayout::Png { bit_depth: 16 }, 2, true);
    let m = dir.path().join("acquisition.toml");
    let good = std::fs::read_to_string(&m).unwrap();
    let cases = [
        (
            good.replace(
                "format = \"mfd-acquisition/1\"",
                "format = \"mfd-acquisition/9\"",
            ),
            "format",
        ),
        (good.replace("tau = 1.0", "tau = -1.0"), "frame[1].tau"),
        (
            good.replace("tau = 1.0", "tau = 1.0\nexposure = 3"),
            "exposure",
        ),
        (
            good.replacen("file = \"frames/000001.png\"\n", "", 1),
            "frame[1].file",
        ),
        (
            good.replace(
                "station = \"station.toml\"",
                "station = \"station.toml\"\nstack = \"frames.npy\"",
            ),
            "frame[0].file",
        ),
    ];
    for (text, field) in cases {
        std::fs::write(&m, &text).unwrap();
        let err = err_of(dir.path());
        assert!(
            err.contains("acquisition.toml") && err.contains(field),
            "expected `{field}` in: {err}"
        );
    }
}
