//! Tests of the simulated sessions.

use super::*;
use crate::calibrate::session_file::{SessionFile, SESSION_FORMAT};
use crate::formats::image_io::read_gray;

#[test]
fn a_session_folder_reads_back() {
    let truth = example_truth().unwrap();
    let spec = SessionSpec {
        targets_grid: [3, 2],
        ..SessionSpec::default()
    };
    let sim = simulate_session(&truth, &spec).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_session(&sim, dir.path()).unwrap();
    let text = std::fs::read_to_string(dir.path().join("session.toml")).unwrap();
    let file: SessionFile = toml::from_str(&text).unwrap();
    assert_eq!(file.format, SESSION_FORMAT);
    assert_eq!(file.target_point.len(), sim.input.targets.len());
    assert_eq!(file.reference_flat.acquisition, "flat/acquisition.toml");
    Station::load(&dir.path().join(&file.nominal_station)).unwrap();
    let t = &sim.input.targets[0];
    let img = read_gray(
        &dir.path()
            .join(file.target_point[0].image.as_ref().unwrap()),
    )
    .unwrap();
    assert_eq!(
        (img.width, img.height, img.bit_depth),
        (truth.camera.width, truth.camera.height, 16)
    );
    // The brightest pixel is the one under the spot's centre.
    let (k, _) = img
        .data
        .iter()
        .enumerate()
        .max_by_key(|(_, v)| **v)
        .unwrap();
    let (i, j) = (
        (k % img.width as usize) as f64,
        (k / img.width as usize) as f64,
    );
    assert!((i + 0.5 - t.pixel.x).abs() <= 1.0 && (j + 0.5 - t.pixel.y).abs() <= 1.0);
}

#[test]
fn the_simulated_readings_carry_the_stated_noise() {
    let truth = example_truth().unwrap();
    let sim = simulate_session(&truth, &SessionSpec::default()).unwrap();
    // Flat points lie on the true plane to the stage noise: RMS of 9
    // N(0, 1 µm) heights is within 1 µm · (1 ± 4·√(1/18)).
    let z: Vec<f64> = sim
        .input
        .flat_points_stage_mm
        .iter()
        .map(|p| sim.frame.to_world(p).z)
        .collect();
    let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    assert!(
        (rms / 1e-3 - 1.0).abs() < 4.0 * (1.0_f64 / 18.0).sqrt(),
        "{rms}"
    );
    // Targets at two or more heights, spread over the sensor.
    let heights: Vec<f64> = sim
        .input
        .targets
        .iter()
        .map(|t| sim.frame.to_world(&t.stage_mm).z.round())
        .collect();
    assert!(heights.contains(&0.0) && heights.contains(&120.0));
    let xs: Vec<f64> = sim.input.targets.iter().map(|t| t.pixel.x).collect();
    let spread =
        xs.iter().copied().fold(f64::MIN, f64::max) - xs.iter().copied().fold(f64::MAX, f64::min);
    assert!(spread > 0.8 * f64::from(truth.camera.width));
}

#[test]
fn screen_points_reach_the_session_file_and_read_back() {
    // A session with marks writes `[[screen_point]]` entries that the
    // session reader takes; the same seed without marks is the session it
    // always was (the marks are drawn last).
    let truth = example_truth().unwrap();
    let spec = SessionSpec {
        targets_grid: [3, 2],
        screen_points: [3, 2],
        ..SessionSpec::default()
    };
    let sim = simulate_session(&truth, &spec).unwrap();
    let plain = simulate_session(
        &truth,
        &SessionSpec {
            screen_points: [0, 0],
            ..spec.clone()
        },
    )
    .unwrap();
    assert_eq!(sim.input.targets, plain.input.targets);
    assert_eq!(sim.input.screen_points.len(), 6);
    assert!(plain.input.screen_points.is_empty());
    let dir = tempfile::tempdir().unwrap();
    write_session(&sim, dir.path()).unwrap();
    let text = std::fs::read_to_string(dir.path().join("session.toml")).unwrap();
    let file: SessionFile = toml::from_str(&text).unwrap();
    assert_eq!(file.screen_point.len(), 6);
    for (m, f) in sim.input.screen_points.iter().zip(&file.screen_point) {
        assert_eq!(f.screen_px, [m.screen_px.x, m.screen_px.y]);
        // Each reading is the mark's focus to the stage noise: within
        // 5 σ of 1 µm plus the focus spread (tens of µm) of the true one.
        let focus = crate::calibrate::screen_mark::mark_focus(
            &truth.screen,
            &nalgebra::Unit::new_normalize(sim.frame.stage_from_world().inverse() * Vector3::z()),
            m.screen_px.x,
            m.screen_px.y,
        );
        let spread = (12.0 * focus.focus_cov_mm2.trace()).sqrt();
        let off = (sim.frame.to_world(&Vector3::from(f.stage_mm)) - focus.world_mm).norm();
        assert!(off < 0.5 * spread + 5e-3, "{off} mm");
    }
}
