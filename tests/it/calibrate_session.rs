//! Calibration sessions end to end, without solving: a good session loads
//! and checks clean; each bad session of issue 14's "Bad sessions" (too few
//! or collinear flat points, coplanar targets, a target frame of the wrong
//! size, a stage reading in the wrong units) gives an error that names the
//! entry and says what to do; the template round-trips through the check;
//! a capture from the simulated target camera appends to the session and
//! is found where the nominal station puts it.
//!
//! The session is made from a known truth: the paper's simulated station
//! (`calib/paper-sim.toml`) as the nominal one, a stage frame shifted and
//! turned against the world, targets planned by `plan_targets`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use mfd::acquire::acquisition::{AcquisitionWriter, FrameImage, FrameInfo, FrameLayout};
use mfd::acquire::camera::CameraConfig;
use mfd::calibrate::check::{check, Severity};
use mfd::calibrate::frame::WorldFrame;
use mfd::calibrate::make::{self, plan_targets};
use mfd::calibrate::session_file::{
    ReferenceFlat, SessionElement, SessionFile, StagePoint, TargetPoint, SESSION_FORMAT,
};
use mfd::calibrate::{Session, SessionError};
use mfd::formats::image_io;
use mfd::optics::station::Station;
use mfd::sim::{render_spot, SpotCamera, SpotScene};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;

fn nominal_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("calib/paper-sim.toml")
}

/// The stage's frame against the world: turned 0.5° about a skew axis and
/// shifted by [100, 80, 20] mm.
fn stage_from_world() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(100.0, 80.0, 20.0),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.004, -0.006, 0.003)),
    )
}

/// The world frame the session defines has x = stage x projected, so the
/// truth is given in world points built on that convention: this test
/// only needs the stage readings to be consistent, not a particular frame.
fn good_file(station: &Station) -> SessionFile {
    let s = stage_from_world();
    let stage = |p: Point3<f64>| (s * p).coords.into();
    let flat = [
        [-30.0, -30.0],
        [30.0, -30.0],
        [30.0, 30.0],
        [-30.0, 30.0],
        [0.0, 5.0],
    ]
    .map(|[x, y]| StagePoint {
        stage_mm: stage(Point3::new(x, y, 0.0)),
    });
    let element = [[-20.0, -20.0], [20.0, -20.0], [0.0, 20.0]].map(|[x, y]| StagePoint {
        stage_mm: stage(Point3::new(x, y, 0.002)),
    });
    let planned = plan_targets(station, None, &[0.0, 20.0, 40.0], (3, 3)).unwrap();
    let target_point = planned
        .iter()
        .map(|t| TargetPoint {
            stage_mm: stage(t.world_mm),
            image: None,
            image_px: Some(t.expected_px.coords.into()),
        })
        .collect();
    let origin = s * Point3::origin();
    SessionFile {
        format: SESSION_FORMAT.into(),
        nominal_station: "nominal.toml".into(),
        stage_std_um: 1.0,
        element: SessionElement {
            center_stage_mm: [origin.x, origin.y],
            thickness_mm: 10.159,
            thickness_std_mm: 0.002,
            refractive_index: 1.5192,
            refractive_index_std: 0.0002,
        },
        flat_point: flat.to_vec(),
        element_point: element.to_vec(),
        target_point,
        screen_point: vec![],
        reference_flat: ReferenceFlat {
            acquisition: "flat/acquisition/acquisition.toml".into(),
            flat_pv_nm: 63.0,
        },
    }
}

/// A session folder: the nominal station, a small reference-flat
/// acquisition, and `file` as session.toml.
fn write_session(dir: &Path, file: &SessionFile) -> PathBuf {
    std::fs::copy(nominal_path(), dir.join("nominal.toml")).unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let (w, h) = (station.camera.width, station.camera.height);
    let frames: Vec<FrameInfo> = (0..2)
        .map(|index| FrameInfo {
            index,
            direction_deg: 45.0,
            tau: 1.0,
            phase_rad: 0.0,
        })
        .collect();
    let acq = dir.join("flat/acquisition");
    let mut writer = AcquisitionWriter::create(
        &acq,
        "../../nominal.toml",
        FrameLayout::Png { bit_depth: 8 },
        &frames,
        w,
        h,
        true,
    )
    .unwrap();
    let data = vec![100u16; (w * h) as usize];
    for k in 0..2 {
        writer
            .write_frame(
                k,
                &FrameImage {
                    width: w,
                    height: h,
                    bit_depth: 8,
                    data: &data,
                },
            )
            .unwrap();
    }
    writer.finish().unwrap();
    rewrite(dir, file)
}

fn rewrite(dir: &Path, file: &SessionFile) -> PathBuf {
    let path = dir.join("session.toml");
    std::fs::write(&path, toml::to_string(file).unwrap()).unwrap();
    path
}

fn load_err(dir: &Path, file: &SessionFile) -> SessionError {
    rewrite(dir, file);
    Session::load(dir).unwrap_err()
}

fn assert_names(err: &SessionError, entry: &str, words: &[&str]) {
    let text = err.to_string();
    assert_eq!(err.entry(), Some(entry), "{text}");
    assert!(
        text.contains("session.toml") && text.contains(entry),
        "{text}"
    );
    for w in words {
        assert!(text.contains(w), "missing {w:?} in: {text}");
    }
}

#[test]
fn a_good_session_loads_and_checks_clean() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    write_session(dir.path(), &good_file(&station));
    let session = Session::load(dir.path()).unwrap();
    assert_eq!(
        (session.flat_points_mm.len(), session.targets.len()),
        (5, 27)
    );
    assert_eq!(session.starting_station().element.thickness_mm, 10.159);
    let report = check(dir.path());
    assert!(report.ready(), "{:#?}", report.findings);
    assert_eq!(report.count(Severity::Warning), 0, "{:#?}", report.findings);
    // The spots are where the nominal station puts them: the stage frame's
    // turn about z is what the world frame's convention absorbs, so every
    // target sits on the pattern.
    assert!(
        report
            .targets
            .iter()
            .all(|t| t.off_pattern_px.is_some_and(|r| r < 1.0)),
        "{:#?}",
        report.targets
    );
}

#[test]
fn too_few_or_collinear_flat_points_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let good = good_file(&station);
    write_session(dir.path(), &good);

    let mut f = good.clone();
    f.flat_point.truncate(2);
    assert_names(
        &load_err(dir.path(), &f),
        "flat_point",
        &["2 given", "at least 3"],
    );

    // Three points on one line, 0.3 µm off it: within 1 µm of stage noise.
    let mut f = good.clone();
    f.flat_point = [0.0, 10.0, 20.0]
        .iter()
        .enumerate()
        .map(|(k, t)| StagePoint {
            stage_mm: [100.0 + t, 80.0 + 0.5 * t, 20.0 + 3e-4 * (k % 2) as f64],
        })
        .collect();
    assert_names(
        &load_err(dir.path(), &f),
        "flat_point",
        &["lie on one line", "add a point"],
    );

    // Two element points: none or at least 3.
    let mut f = good.clone();
    f.element_point.truncate(2);
    assert_names(&load_err(dir.path(), &f), "element_point", &["at least 3"]);
}

#[test]
fn coplanar_targets_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let mut f = good_file(&station);
    write_session(dir.path(), &f);
    let planned = plan_targets(&station, None, &[10.0, 10.000_5], (3, 3)).unwrap();
    let s = stage_from_world();
    for (t, p) in f.target_point.iter_mut().zip(&planned) {
        t.stage_mm = (s * p.world_mm).coords.into();
    }
    f.target_point.truncate(planned.len());
    // 0.5 µm apart in height with 1 µm stage noise: one plane.
    assert_names(
        &load_err(dir.path(), &f),
        "target_point",
        &["lie in one plane", "two or more heights"],
    );
}

#[test]
fn stage_readings_in_the_wrong_units_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let good = good_file(&station);
    write_session(dir.path(), &good);

    let mut f = good.clone();
    f.target_point[4].stage_mm = f.target_point[4].stage_mm.map(|v| v * 1000.0);
    assert_names(
        &load_err(dir.path(), &f),
        "target_point[4].stage_mm",
        &["µm written for mm", "divide by 1000"],
    );

    let mut f = good.clone();
    let m = |p: [f64; 3]| p.map(|v| v / 1000.0);
    f.flat_point
        .iter_mut()
        .for_each(|p| p.stage_mm = m(p.stage_mm));
    f.element_point
        .iter_mut()
        .for_each(|p| p.stage_mm = m(p.stage_mm));
    f.target_point
        .iter_mut()
        .for_each(|p| p.stage_mm = m(p.stage_mm));
    f.element.center_stage_mm = f.element.center_stage_mm.map(|v| v / 1000.0);
    assert_names(
        &load_err(dir.path(), &f),
        "flat_point[0].stage_mm",
        &["m written for mm", "multiply by 1000"],
    );

    let mut f = good.clone();
    f.stage_std_um = 0.001;
    assert_names(
        &load_err(dir.path(), &f),
        "stage_std_um",
        &["0.001 µm", "check its unit"],
    );
}

#[test]
fn other_bad_entries_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let good = good_file(&station);
    write_session(dir.path(), &good);
    let mut f = good.clone();
    f.target_point[3].image = Some("targets/003.png".into());
    assert_names(
        &load_err(dir.path(), &f),
        "target_point[3]",
        &["both `image` and `image_px`"],
    );
    let mut f = good.clone();
    f.target_point[3].image_px = None;
    f.target_point[3].image = Some("targets/003.png".into());
    assert_names(
        &load_err(dir.path(), &f),
        "target_point[3].image",
        &["does not exist", "capture it"],
    );
    let mut f = good.clone();
    f.element.refractive_index_std = 0.0;
    assert_names(
        &load_err(dir.path(), &f),
        "element.refractive_index_std",
        &["> 0"],
    );
    let mut f = good.clone();
    f.format = "mfd-calibration/2".into();
    assert_names(&load_err(dir.path(), &f), "format", &["mfd-calibration/1"]);
    // The check lists every problem, not only the first.
    let mut f = good.clone();
    f.flat_point.truncate(1);
    f.target_point.truncate(3);
    rewrite(dir.path(), &f);
    let report = check(dir.path());
    let entries: Vec<_> = report
        .findings
        .iter()
        .filter(|x| x.severity == Severity::Error)
        .filter_map(|x| x.entry.clone())
        .collect();
    assert!(
        entries.contains(&"flat_point".into()) && entries.contains(&"target_point".into()),
        "{entries:?}"
    );
}

#[test]
fn a_target_frame_of_the_wrong_size_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let mut f = good_file(&station);
    write_session(dir.path(), &f);
    std::fs::create_dir_all(dir.path().join("targets")).unwrap();
    let scene = SpotScene {
        resolution: (640, 480),
        bit_depth: 16,
        centre_px: Some(Point2::new(320.0, 240.0)),
        sigma_px: 1.5,
        peak_counts: 20000.0,
        ambient_counts: 1000.0,
        gradient_counts_per_px: [0.0, 0.0],
        noise_counts: 50.0,
    };
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
    let file = dir.path().join("targets/005.png");
    image_io::write_png(&file, 640, 480, 16, &render_spot(&scene, &mut rng)).unwrap();
    f.target_point[5].image_px = None;
    f.target_point[5].image = Some("targets/005.png".into());
    rewrite(dir.path(), &f);
    let session = Session::load(dir.path()).unwrap();
    let err = session.centroids().unwrap_err().to_string();
    assert!(
        err.contains("target_point[5]")
            && err.contains("005.png")
            && err.contains("640x480")
            && err.contains("1296x966"),
        "{err}"
    );
    let report = check(dir.path());
    let finding = report
        .findings
        .iter()
        .find(|x| x.entry.as_deref() == Some("target_point[5]"))
        .unwrap();
    assert_eq!(finding.severity, Severity::Error);
    assert!(
        finding.message.contains("full resolution"),
        "{}",
        finding.message
    );
}

mod template;
