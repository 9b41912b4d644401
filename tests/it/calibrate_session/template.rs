//! The session template and the capture step: the template round-trips
//! through the check, captures from the simulated target camera append to
//! it and a wrong stage reading is flagged, and the CLI writes and checks a
//! template.

use super::*;

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
