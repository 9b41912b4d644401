//! Structure-aware fuzzing of every reader (issue 19): valid files — the
//! shared fixtures and files the library writes — mutated the ways real
//! files go wrong (lines deleted or duplicated, numbers replaced by NaN,
//! ±inf, −0, 1e308, huge or negative integers, arrays grown or shrunk, the
//! file cut at any byte, bytes flipped; NPY headers with other shapes,
//! dtypes and lengths; PNG/TIFF headers and chunks corrupted). For every
//! reader: no panic, no abort (a reader allocating what a header announces
//! would abort the whole test binary), no hang (each call runs on its own
//! thread and must return within [`CALL_LIMIT`]).
//!
//! Budget: [`CASES`] inputs per base file (override with `MFD_FUZZ_CASES`),
//! seeded, so a run is repeatable: 19 base files × 1 500 = 28 500 inputs,
//! 11 s of CPU and 25 s wall in the test profile on the 2-core CI machine
//! under a load of 5 (the whole file stays under 60 s). Longer runs were
//! clean: 4 000 per base (76 000 inputs), 20 000 per base for all but the
//! profiles (340 000). A failure prints the shrunk input; it then becomes a
//! unit test beside its reader.

use crate::common;

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

use mfd::acquire::acquisition::{check_against_station, Acquisition};
use mfd::acquire::schedule_file;
use mfd::calibrate::Session;
use mfd::formats::image_io;
use mfd::formats::npy::{self, NpyStackReader, NpyStackWriter, StackDtype};
use mfd::formats::surfaces_file::SurfacesFile;
use mfd::optics::station::{Station, StationUncertainty};

mod edits;
use edits::{apply, edits, Kind};

/// Inputs per base file: keeps the file well under a minute (see the head).
const CASES: u32 = 1500;

/// The longest one reader call may take before it counts as a hang. The
/// slowest reader here (a station v2 with distortion, 18×18 Newton solves)
/// takes ~1 ms; 10 s is four orders of magnitude above it, so only a loop
/// that does not end (or an allocation of what a corrupt header announces)
/// reaches it.
const CALL_LIMIT: Duration = Duration::from_secs(10);

fn cases() -> u32 {
    std::env::var("MFD_FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(CASES)
}

/// Runs `f` on its own thread: a panic or a call longer than [`CALL_LIMIT`]
/// is a failed case.
fn bounded<F: FnOnce() + Send + 'static>(what: &str, f: F) -> Result<(), TestCaseError> {
    let (tx, rx) = mpsc::channel();
    let handle = std::thread::spawn(move || {
        f();
        let _ = tx.send(());
    });
    match rx.recv_timeout(CALL_LIMIT) {
        Ok(()) => {
            handle.join().ok();
            Ok(())
        }
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            let msg = match handle.join() {
                Err(e) => e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default(),
                Ok(()) => String::new(),
            };
            Err(TestCaseError::fail(format!("{what} panicked: {msg}")))
        }
        Err(mpsc::RecvTimeoutError::Timeout) => Err(TestCaseError::fail(format!(
            "{what} did not return within {CALL_LIMIT:?}"
        ))),
    }
}

/// Drives `check` over `cases()` mutations of `base` with a seeded runner.
fn fuzz(seed: u8, base: Vec<u8>, kind: Kind, check: impl Fn(Vec<u8>) -> Result<(), TestCaseError>) {
    let config = Config {
        cases: cases(),
        failure_persistence: None,
        ..Config::default()
    };
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32]);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let base = std::sync::Arc::new(base);
    let strategy = edits(kind);
    let result = runner.run(&strategy, |edits| {
        let input = apply(&base, &edits);
        check(input)
    });
    if let Err(e) = result {
        panic!("{e}");
    }
}

/// A fresh folder for one case's files.
fn case_dir() -> tempfile::TempDir {
    tempfile::tempdir().expect("temp dir")
}

fn fixture(path: &str) -> PathBuf {
    common::public_small().join(path)
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A version-2 station: the fixture's with distortion, cover glass and pose.
fn station_v2_text() -> String {
    let v1 = String::from_utf8(read(&fixture("station.toml"))).unwrap();
    v1.replace("mfd-station/1", "mfd-station/2")
        .replace(
            "[screen]",
            "[camera.distortion]\nmodel = \"brown-conrady\"\nk = [-0.02, 0.001, 0.0]\n\
             p = [0.0001, -0.0002]\n\n[screen]",
        )
        .replace(
            "[element]",
            "[screen.cover_glass]\nthickness_mm = 1.8\nrefractive_index = 1.52\n\n[element]",
        )
        + "offset_mm = [0.0, 0.0, 0.012]\ntilt_deg = [0.8, -0.1]\n"
}

#[test]
fn station_files() {
    let bases = [
        read(&fixture("station.toml")),
        station_v2_text().into_bytes(),
        read(&common::repo("calib/paper-sim.toml")),
    ];
    for (k, base) in bases.into_iter().enumerate() {
        assert!(
            Station::from_toml_str(std::str::from_utf8(&base).unwrap(), Path::new("s")).is_ok()
        );
        fuzz(1 + k as u8, base, Kind::Text, |input| {
            bounded("Station::load", move || {
                let dir = case_dir();
                let path = dir.path().join("station.toml");
                std::fs::write(&path, input).unwrap();
                let _ = Station::load(&path);
            })
        });
    }
}

#[test]
fn station_uncertainty_files() {
    let base = read(&common::repo("calib/paper-sim.uncertainty.toml"));
    let with_cov = String::from_utf8(base.clone()).unwrap()
        + "\n[covariance]\nnames = [\"camera.x_mm\", \"camera.z_mm\"]\n\
           matrix = [[0.04, 0.01], [0.01, 0.25]]\n";
    for (k, base) in [base, with_cov.into_bytes()].into_iter().enumerate() {
        assert!(StationUncertainty::from_toml_str(
            std::str::from_utf8(&base).unwrap(),
            Path::new("u")
        )
        .is_ok());
        fuzz(10 + k as u8, base, Kind::Text, |input| {
            bounded("StationUncertainty::load", move || {
                let dir = case_dir();
                let path = dir.path().join("u.toml");
                std::fs::write(&path, input).unwrap();
                let _ = StationUncertainty::load(&path);
            })
        });
    }
}

#[test]
fn schedule_files() {
    let dir = case_dir();
    let path = dir.path().join("s.toml");
    let frames = mfd::acquire::acquisition::FrameInfo::from_patterns(
        &mfd::acquire::patterns::Schedule {
            tau_stop: 2.0,
            ..Default::default()
        }
        .patterns(),
    );
    schedule_file::write(&path, &frames, "fuzz base").unwrap();
    fuzz(20, read(&path), Kind::Text, |input| {
        bounded("schedule_file::load", move || {
            let dir = case_dir();
            let path = dir.path().join("s.toml");
            std::fs::write(&path, input).unwrap();
            if let Ok(file) = schedule_file::load(&path) {
                let _ = file.check_against_screen(&path, 1600, 1200);
                let _ = file.patterns();
            }
        })
    });
}

/// A stack acquisition the library writes: 3 frames of the fixture camera.
fn stack_acquisition(dir: &Path) {
    std::fs::copy(fixture("station.toml"), dir.join("station.toml")).unwrap();
    let mut w =
        NpyStackWriter::create(&dir.join("frames.npy"), StackDtype::U16, 3, 48, 48).unwrap();
    for k in 0..3u16 {
        w.append(&vec![k * 1000; 48 * 48]).unwrap();
    }
    w.finish().unwrap();
    let manifest =
        "format = \"mfd-acquisition/1\"\nstation = \"station.toml\"\nstack = \"frames.npy\"\n\n\
        [[frame]]\ndirection_deg = 45.0\ntau = 0.5\n\n\
        [[frame]]\ndirection_deg = 45.0\ntau = 1.0\nphase_rad = 0.0\n\n\
        [[frame]]\ndirection_deg = -45.0\ntau = 1.5\n";
    std::fs::write(dir.join("acquisition.toml"), manifest).unwrap();
}

/// Opens, checks against the station and reads every frame, as
/// `pipeline::reconstruct` does.
fn use_acquisition(dir: &Path) {
    let Ok(mut acq) = Acquisition::open(dir) else {
        return;
    };
    let Ok(station) = Station::load(acq.station_path()) else {
        return;
    };
    if check_against_station(&acq, &station).is_err() {
        return;
    }
    if acq
        .check_resolution(station.camera.width, station.camera.height)
        .is_err()
    {
        return;
    }
    let mut frame = Vec::new();
    for k in 0..acq.frames().len().min(4) {
        let _ = acq.read_frame(k, &mut frame);
    }
}

#[test]
fn acquisition_manifests() {
    // Frames as files: the fixture's manifest, its first 4 frames copied.
    let text = String::from_utf8(read(&fixture("acquisition.toml"))).unwrap();
    fuzz(30, text.into_bytes(), Kind::Text, |input| {
        bounded("Acquisition::open (files)", move || {
            let dir = case_dir();
            std::fs::copy(fixture("station.toml"), dir.path().join("station.toml")).unwrap();
            std::fs::create_dir(dir.path().join("frames")).unwrap();
            for k in 0..4 {
                let name = format!("frames/{k:06}.png");
                std::fs::copy(fixture(&name), dir.path().join(&name)).unwrap();
            }
            std::fs::write(dir.path().join("acquisition.toml"), input).unwrap();
            use_acquisition(dir.path());
        })
    });
    let base = case_dir();
    stack_acquisition(base.path());
    fuzz(
        31,
        read(&base.path().join("acquisition.toml")),
        Kind::Text,
        |input| {
            bounded("Acquisition::open (stack)", move || {
                let dir = case_dir();
                stack_acquisition(dir.path());
                std::fs::write(dir.path().join("acquisition.toml"), input).unwrap();
                use_acquisition(dir.path());
            })
        },
    );
    // The stack itself corrupted under a valid manifest.
    fuzz(
        32,
        read(&base.path().join("frames.npy")),
        Kind::Npy,
        |input| {
            bounded("Acquisition stack", move || {
                let dir = case_dir();
                stack_acquisition(dir.path());
                std::fs::write(dir.path().join("frames.npy"), input).unwrap();
                use_acquisition(dir.path());
            })
        },
    );
}

#[test]
fn npy_arrays() {
    let bases = [
        read(&fixture("truth/truth_screen_coords.npy")),
        read(&fixture("truth/aperture_mask.npy")),
    ];
    for (k, base) in bases.into_iter().enumerate() {
        fuzz(40 + k as u8, base, Kind::Npy, |input| {
            bounded("npy::read_*", move || {
                let dir = case_dir();
                let path = dir.path().join("a.npy");
                std::fs::write(&path, input).unwrap();
                let _ = npy::read_f64(&path);
                let _ = npy::read_bool(&path);
                let _ = npy::read_u16(&path);
                if let Ok(mut r) = NpyStackReader::open(&path) {
                    let mut frame = Vec::new();
                    for i in 0..r.frames().min(3) {
                        let _ = r.read_frame(i, &mut frame);
                    }
                }
            })
        });
    }
}

#[test]
fn png_and_tiff_frames() {
    let dir = case_dir();
    let png8 = dir.path().join("f8.png");
    let data: Vec<u16> = (0..48 * 48).map(|k| (k % 251) as u16).collect();
    image_io::write_png(&png8, 48, 48, 8, &data).unwrap();
    let pngs = [read(&fixture("frames/000000.png")), read(&png8)];
    for (k, base) in pngs.into_iter().enumerate() {
        fuzz(50 + k as u8, base, Kind::Png, |input| {
            bounded("image_io::read_gray (png)", move || {
                let dir = case_dir();
                let path = dir.path().join("f.png");
                std::fs::write(&path, input).unwrap();
                let _ = image_io::read_gray(&path);
            })
        });
    }
    let tif = dir.path().join("f.tiff");
    let mut enc = tiff::encoder::TiffEncoder::new(std::fs::File::create(&tif).unwrap()).unwrap();
    enc.write_image::<tiff::encoder::colortype::Gray16>(48, 48, &data)
        .unwrap();
    drop(enc);
    fuzz(52, read(&tif), Kind::Binary, |input| {
        bounded("image_io::read_gray (tiff)", move || {
            let dir = case_dir();
            let path = dir.path().join("f.tiff");
            std::fs::write(&path, input).unwrap();
            let _ = image_io::read_gray(&path);
        })
    });
}

const SURFACES_V2: &str = r#"{
  "format": "mfd-surfaces/2",
  "zernike": {"ordering": "noll", "normalization": "rms",
              "radius_mm": 25.5, "center_mm": [0.0, 0.0]},
  "front": {"coefficients_nm": [0.0, 12.5, -3.1, 40.2],
            "std_nm": [0.0, 1.1, 1.0, 0.6],
            "expected_error_rms_nm": 1.9,
            "not_reconstructed_because": null},
  "back": {"coefficients_nm": null, "not_reconstructed_because": "no back reflection"}
}"#;

#[test]
fn surfaces_files() {
    let bases = [
        read(&fixture("truth/truth_surfaces.json")),
        SURFACES_V2.as_bytes().to_vec(),
    ];
    for (k, base) in bases.into_iter().enumerate() {
        assert!(
            SurfacesFile::from_json_str(std::str::from_utf8(&base).unwrap(), Path::new("j"))
                .is_ok()
        );
        fuzz(60 + k as u8, base, Kind::Text, |input| {
            bounded("SurfacesFile::load", move || {
                let dir = case_dir();
                let path = dir.path().join("surfaces.json");
                std::fs::write(&path, input).unwrap();
                if let Ok(f) = SurfacesFile::load(&path) {
                    let _ = f.to_json_string(&path);
                }
            })
        });
    }
}

/// A valid session over the fixture station: flat and element points,
/// six targets at two heights given as centroids.
const SESSION: &str = r#"format = "mfd-calibration/1"
nominal_station = "nominal.toml"
stage_std_um = 1.0

[element]
center_stage_mm = [100.0, 80.0]
thickness_mm = 10.0
thickness_std_mm = 0.002
refractive_index = 1.5
refractive_index_std = 0.0002

[[flat_point]]
stage_mm = [70.0, 50.0, 20.0]
[[flat_point]]
stage_mm = [130.0, 50.0, 20.001]
[[flat_point]]
stage_mm = [130.0, 110.0, 20.0]
[[flat_point]]
stage_mm = [70.0, 110.0, 19.999]

[[element_point]]
stage_mm = [90.0, 70.0, 20.002]
[[element_point]]
stage_mm = [110.0, 70.0, 20.002]
[[element_point]]
stage_mm = [100.0, 95.0, 20.002]

[[target_point]]
stage_mm = [90.0, 70.0, 30.0]
image_px = [12.5, 14.0]
[[target_point]]
stage_mm = [110.0, 70.0, 30.0]
image_px = [30.5, 13.0]
[[target_point]]
stage_mm = [100.0, 95.0, 30.0]
image_px = [22.0, 34.5]
[[target_point]]
stage_mm = [90.0, 70.0, 60.0]
image_px = [10.5, 12.0]
[[target_point]]
stage_mm = [110.0, 70.0, 60.0]
image_px = [33.5, 11.0]
[[target_point]]
stage_mm = [100.0, 95.0, 60.0]
image_px = [22.0, 37.5]

[[screen_point]]
stage_mm = [105.0, 242.0, 845.0]
screen_px = [400.5, 300.5]

[reference_flat]
acquisition = "flat/acquisition.toml"
flat_pv_nm = 63.0
"#;

#[test]
fn calibration_sessions() {
    let write = |dir: &Path, text: &[u8]| {
        std::fs::copy(fixture("station.toml"), dir.join("nominal.toml")).unwrap();
        std::fs::create_dir(dir.join("flat")).unwrap();
        std::fs::copy(
            fixture("acquisition.toml"),
            dir.join("flat/acquisition.toml"),
        )
        .unwrap();
        std::fs::write(dir.join("session.toml"), text).unwrap();
    };
    let base = case_dir();
    write(base.path(), SESSION.as_bytes());
    if let Err(e) = Session::load(base.path()) {
        panic!("the base session must load: {e}");
    }
    fuzz(70, SESSION.as_bytes().to_vec(), Kind::Text, |input| {
        bounded("Session::load", move || {
            let dir = case_dir();
            write(dir.path(), &input);
            if let Ok(s) = Session::load(dir.path()) {
                let _ = s.centroids();
            }
        })
    });
}

#[test]
fn hardware_profiles() {
    use mfd::optics::station::{CameraProfile, DisplayProfile};
    let camera = read(&common::repo("hw/camera/baumer-txg12.toml"));
    fuzz(80, camera, Kind::Text, |input| {
        bounded("CameraProfile::load", move || {
            let dir = case_dir();
            let path = dir.path().join("c.toml");
            std::fs::write(&path, input).unwrap();
            let _ = CameraProfile::load(&path);
        })
    });
    let display = read(&common::repo("hw/display/mtiph-e2m21gm.toml"));
    fuzz(81, display, Kind::Text, |input| {
        bounded("DisplayProfile::load", move || {
            let dir = case_dir();
            let path = dir.path().join("d.toml");
            std::fs::write(&path, input).unwrap();
            if let Ok(d) = DisplayProfile::load(&path) {
                let _ = mfd::acquire::display::offscreen::settle_time(&d);
            }
        })
    });
}
