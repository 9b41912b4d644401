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

/// A template session (nominal copied in), checked as written.
fn template(dir: &Path, station: &Station) -> (PathBuf, PathBuf) {
    let session = dir.join("s");
    let path = make::write_template(&session, Some((&nominal_path(), station))).unwrap();
    (session, path)
}

fn error_entries(session: &Path) -> Vec<String> {
    check(session)
        .findings
        .iter()
        .filter(|x| x.severity == Severity::Error)
        .filter_map(|x| x.entry.clone())
        .collect()
}

#[test]
fn the_template_round_trips_through_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let (session, _) = template(dir.path(), &station);
    assert!(session.join("targets").is_dir() && session.join("nominal.toml").is_file());
    assert!(matches!(
        make::write_template(&session, None),
        Err(make::MakeError::Exists { .. })
    ));
    // The template parses; the check says what is missing, in entries.
    assert_eq!(
        error_entries(&session),
        ["reference_flat.acquisition", "flat_point", "target_point"]
    );
    let report = check(&session);
    assert!(report.findings.iter().any(|f| f.severity == Severity::Note
        && f.message
            .contains("the element is taken to stand on the reference plane")));
    let loaded = mfd::calibrate::session::read_file(&session.join("session.toml")).unwrap();
    assert_eq!(loaded.element.thickness_mm, station.element.thickness_mm);
}

#[test]
fn captures_append_to_the_template_and_the_check_flags_a_wrong_reading() {
    let dir = tempfile::tempdir().unwrap();
    let station = Station::load(&nominal_path()).unwrap();
    let (session, path) = template(dir.path(), &station);
    // Fill it: flat and element points as text, targets captured from the
    // simulated target camera where the nominal station images them.
    let good = good_file(&station);
    let mut text = std::fs::read_to_string(&path).unwrap();
    text = text.replace(
        "center_stage_mm = [0.0, 0.0]",
        &format!("center_stage_mm = {:?}", good.element.center_stage_mm),
    );
    for p in &good.flat_point {
        text.push_str(&format!("\n[[flat_point]]\nstage_mm = {:?}\n", p.stage_mm));
    }
    std::fs::write(&path, text).unwrap();
    write_session_acquisition_only(&session, &station);
    let s = stage_from_world();
    let planned = plan_targets(&station, None, &[0.0, 30.0], (3, 3)).unwrap();
    // The session's world frame is turned about z against the truth's (its
    // x is the stage x projected): the simulated camera images the targets
    // through the frame the session defines, as the check predicts them.
    let flat: Vec<_> = good
        .flat_point
        .iter()
        .map(|p| Point3::from(p.stage_mm))
        .collect();
    let frame = WorldFrame::from_flat_points(&flat, good.element.center_stage_mm, 1e-3).unwrap();
    for (k, t) in planned.iter().enumerate() {
        let stage: [f64; 3] = (s * t.world_mm).coords.into();
        let seen = station
            .camera
            .project(&frame.to_world(&Point3::from(stage)))
            .unwrap();
        let mut cam = SpotCamera::new(spot_at(&station, seen), k as u64);
        let got = make::capture_target(
            &session,
            stage,
            &mut cam,
            &CameraConfig::default(),
            Duration::from_secs(1),
        )
        .unwrap();
        assert_eq!(
            (got.index, got.image.as_str()),
            (k, format!("targets/{k:03}.png").as_str())
        );
        let c = got.centroid.unwrap();
        let p = got.predicted_px.unwrap();
        // The spot was rendered at the nominal prediction: found within 5σ
        // of its own centroid σ (2-D: exceeded with probability e^-12.5).
        let err = (c.position_px - p).norm();
        assert!(
            err < 5.0 * c.std_px()[0].max(c.std_px()[1]),
            "target {k}: {err} px"
        );
    }
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("# Step 4: a point target"), "comments kept");
    let report = check(&session);
    assert!(report.ready(), "{:#?}", report.findings);
    let loaded = Session::load(&session).unwrap();
    let found = loaded.centroids().unwrap();
    assert_eq!(found.len(), planned.len());
    assert!(found.iter().all(|t| t.covariance_px2.is_some()));

    // A reading entered wrongly (x off by 5 mm) is flagged as such.
    let mut file: SessionFile = toml::from_str(&text).unwrap();
    file.target_point[4].stage_mm[0] += 5.0;
    rewrite(&session, &file);
    let report = check(&session);
    let flagged = report
        .findings
        .iter()
        .find(|x| x.entry.as_deref() == Some("target_point[4]"))
        .unwrap();
    assert!(
        flagged.message.contains("wrong reading?") && flagged.severity == Severity::Warning,
        "{:#?}",
        report.findings
    );
}

fn write_session_acquisition_only(dir: &Path, station: &Station) {
    let (w, h) = (station.camera.width, station.camera.height);
    let frames = [FrameInfo {
        index: 0,
        direction_deg: 45.0,
        tau: 1.0,
        phase_rad: 0.0,
    }];
    let mut writer = AcquisitionWriter::create(
        &dir.join("flat/acquisition"),
        "../../nominal.toml",
        FrameLayout::Png { bit_depth: 8 },
        &frames,
        w,
        h,
        true,
    )
    .unwrap();
    let data = vec![100u16; (w * h) as usize];
    writer
        .write_frame(
            0,
            &FrameImage {
                width: w,
                height: h,
                bit_depth: 8,
                data: &data,
            },
        )
        .unwrap();
    writer.finish().unwrap();
}

fn spot_at(station: &Station, centre: Point2<f64>) -> SpotScene {
    SpotScene {
        resolution: (station.camera.width, station.camera.height),
        bit_depth: 16,
        centre_px: Some(centre),
        sigma_px: 1.5,
        peak_counts: 30000.0,
        ambient_counts: 3000.0,
        gradient_counts_per_px: [1.0, 0.5],
        noise_counts: 200.0,
    }
}

#[test]
fn the_cli_writes_a_template_and_checks_it() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("s");
    let mfd = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_mfd"))
            .args(args)
            .output()
            .unwrap()
    };
    let out = mfd(&[
        "calibrate",
        "template",
        session.to_str().unwrap(),
        "--nominal",
        nominal_path().to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = mfd(&["calibrate", "check", session.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        !out.status.success() && stdout.contains("error: [flat_point] 0 given"),
        "{stdout}"
    );
    let out = mfd(&[
        "calibrate",
        "targets",
        "--nominal",
        nominal_path().to_str().unwrap(),
        "--heights",
        "0,25",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.matches("[[target_point]]").count() == 18,
        "{stdout}"
    );
    // A capture from the simulated target camera (no flat points yet: the
    // spot at the sensor's centre) writes the frame and appends the entry.
    let cap = mfd(&[
        "calibrate",
        "capture",
        session.to_str().unwrap(),
        "--stage-mm",
        "-1.5,2,3",
        "--camera",
        "sim",
    ]);
    let said = String::from_utf8_lossy(&cap.stdout);
    assert!(
        cap.status.success(),
        "{}",
        String::from_utf8_lossy(&cap.stderr)
    );
    assert!(
        said.contains("target_point[0]: wrote targets/000.png") && said.contains("spot at (648"),
        "{said}"
    );
    let file = mfd::calibrate::session::read_file(&session.join("session.toml")).unwrap();
    assert_eq!(file.target_point[0].stage_mm, [-1.5, 2.0, 3.0]);
    // What it prints is TOML a session takes as is.
    let parsed: toml::Value = toml::from_str(&stdout).unwrap();
    assert_eq!(parsed["target_point"].as_array().unwrap().len(), 18);
}
