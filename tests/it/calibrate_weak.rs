//! Issue 35's sessions: a narrow-field camera (±2.3°, f = 60 mm on a
//! 1296 × 966 sensor of 3.75 µm) 850 mm away and tilted 15°, 75 targets on
//! three layers close together over the central 60 % of the sensor,
//! centroids good to 0.08 px. The layers' small spread in depth leaves a
//! "dolly zoom" (camera and screen sliding along the line of sight while
//! the focal length follows) nearly undetermined by the targets. With
//! layers 2 mm apart (σ(camera.z) ≈ 13 mm from the session, above its
//! 10 mm prior) the joint adjustment crawled and stopped at 200 trials
//! before the priors were in its cost (`calibrate::adjust`); here it must
//! converge, name the weak combination in its report and in
//! `station_uncertainty.toml`, and bring the truth back within its
//! covariance; `mfd calibrate check` must warn about the layout first and
//! say how far apart the layers should be.

use std::path::Path;

use mfd::calibrate::calibration::calibrate;
use mfd::calibrate::check::{check, Severity};
use mfd::calibrate::simulate::{flat_truth, simulate_session, write_session, SessionSpec};
use mfd::optics::station::{
    CameraProfile, CoverGlass, DisplayProfile, Distortion, Dof, Station, SymmetricLayout,
};

use crate::calibrate_adjust::chi2_of_errors;

/// The narrow-field station of the issue, with a mildly distorted lens,
/// the screen behind a 1.8 mm cover glass, camera and screen turned off
/// the symmetric layout and the element tilted by 0.6°.
fn narrow_truth() -> Station {
    let layout = SymmetricLayout {
        camera_height_mm: 850.0,
        screen_height_mm: 850.0,
        tilt_deg: 15.0,
        focal_length_mm: 60.0,
        element: SymmetricLayout::paper_element(),
    };
    let camera = CameraProfile {
        format: "mfd-camera-profile/1".into(),
        model: "narrow field".into(),
        resolution: [1296, 966],
        pixel_pitch_um: 3.75,
        bit_depth: 12,
        distortion: None,
    };
    let mut s = layout.build(&camera, &DisplayProfile::paper_lcd()).unwrap();
    s.camera.distortion = Some(Distortion {
        k: [-0.02, 0.0, 0.0],
        p: [0.0, 0.0],
    });
    s.screen.cover_glass = Some(CoverGlass {
        thickness_mm: 1.8,
        refractive_index: 1.52,
    });
    for (name, d) in [
        (Dof::CameraRx, 0.3),
        (Dof::CameraRz, -0.4),
        (Dof::ScreenRy, 0.5),
    ] {
        s = s.perturbed(name, d);
    }
    s.element.pose.tilt_deg = [0.6, -0.3];
    Station::from_file(&s.to_file(), Path::new("<narrow truth>")).unwrap()
}

/// The χ²(30) quantile at 0.999: the error vector of a session with 30
/// parameters is consistent with its covariance at p ≥ 0.001 (issue 35's
/// line) below it.
const CHI2_30_AT_0_999: f64 = 59.703;

/// The layout: 5 × 5 targets on each of three layers `dz_mm`
/// apart over the central 60 % of the sensor, 0.08 px centroids, the
/// Ø 80 mm flat the narrow field sees.
fn narrow_spec(seed: u64, dz_mm: f64) -> SessionSpec {
    SessionSpec {
        seed,
        centroid_std_px: 0.08,
        target_heights_mm: vec![0.0, dz_mm, 2.0 * dz_mm],
        targets_grid: [5, 5],
        target_span: 0.6,
        flat_radius_mm: 40.0,
        ..SessionSpec::default()
    }
}

#[test]
fn close_layers_calibrate_and_name_the_weak_direction() {
    // Layers 2 mm apart: the weak case (σ(camera.z) from the session alone
    // above its 10 mm prior). What holds, on 12 seeds:
    // - every session converges, within 60 trials (it crawled past 200
    //   before the priors were in the cost; measured now: at most 33);
    // - the dolly (camera.z among a weak direction's three largest
    //   components) is named in every one;
    // - the flat-reflected screen points over the flat are within the
    //   issue's 0.05 px of the truth (measured: 0.0077 px at worst);
    // - each parameter alone is within its σ: its (error/σ)² averages
    //   1 ± √(2/N) over N seeds, and 4.5 of those σ (false alarm < 1e-4
    //   over 30 parameters) catch a σ off by 1.7× either way.
    // - the χ² of the whole error vector against the full covariance
    //   (k = 30) at p ≥ 0.001 in every seed (χ²(30) below 59.70): along the
    //   camera's pointing the session pins a combination to ~1e-7 rad, and
    //   the truth lay 5–20 of those σ off it on half the seeds until
    //   `calibrate::valley` took the second-order bend of pairs of long
    //   directions and of the held parameters' draws (measured 10.7–40.6).
    let truth = narrow_truth();
    let seeds = 12;
    let mut weak_named = 0;
    let mut worst_px = 0.0_f64;
    let mut max_trials = 0;
    let mut worst_chi2 = 0.0_f64;
    let mut each: std::collections::BTreeMap<String, f64> = Default::default();
    for seed in 0..seeds {
        let sim = simulate_session(&truth, &narrow_spec(seed, 2.0)).unwrap();
        let cal = calibrate(&sim.input)
            .unwrap_or_else(|e| panic!("seed {seed}: the session does not calibrate: {e}"));
        let (chi2, n, per) = chi2_of_errors(&sim, &cal);
        assert_eq!(n, 30, "the χ² bound below is for 30 parameters");
        worst_chi2 = worst_chi2.max(chi2);
        for (name, z2) in per {
            *each.entry(name).or_default() += z2 / seeds as f64;
        }
        let joint = cal.report.steps.last().unwrap();
        println!(
            "seed {seed}: χ² of the errors {chi2:.1} over {n}, {} trials ({}), {} weak",
            joint.trials,
            joint.stop,
            joint.weak.len()
        );
        max_trials = max_trials.max(joint.trials);
        if joint.weak.iter().any(|w| {
            w.components
                .iter()
                .take(3)
                .any(|(name, _)| name == "camera.z_mm")
        }) {
            weak_named += 1;
        }
        for j in (0..truth.camera.height).step_by(37) {
            for i in (0..truth.camera.width).step_by(37) {
                let Some((t, hit)) = flat_truth(&sim.truth, i, j) else {
                    continue;
                };
                if hit.coords.xy().norm() > 40.0 {
                    continue;
                }
                let (e, _) = cal.flat_screen_point(i, j).unwrap();
                worst_px = worst_px.max((e - t).norm());
            }
        }
    }
    println!(
        "worst flat point {worst_px:.4} px; at most {max_trials} trials; camera.z named weak in \
         {weak_named} of {seeds}"
    );
    assert!(max_trials <= 60, "{max_trials} trials");
    assert!(
        worst_chi2 < CHI2_30_AT_0_999,
        "χ² of the errors {worst_chi2:.1} over 30 (p < 0.001)"
    );
    assert_eq!(weak_named, seeds, "camera.z in a weak direction");
    assert!(
        worst_px < 0.05,
        "worst flat-reflected screen point {worst_px} px"
    );
    let tol = 4.5 * (2.0 / seeds as f64).sqrt();
    for (name, m) in &each {
        assert!(
            (m - 1.0).abs() < tol,
            "{name}: mean (error/σ)² {m:.2} (±{tol:.2})"
        );
    }
}

/// The session's targets as centroids (`image_px`, taken at the given
/// centroids' σ of 0.1 px, near the 0.08) instead of the rendered
/// frames, whose clean spots centroid to 0.016 px.
fn given_centroids(dir: &Path, sim: &mfd::calibrate::simulate::SimulatedSession) {
    let path = dir.join("session.toml");
    let mut doc: toml::Value = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let targets = doc["target_point"].as_array_mut().unwrap();
    for (t, truth) in targets.iter_mut().zip(&sim.input.targets) {
        let t = t.as_table_mut().unwrap();
        t.remove("image");
        t.insert(
            "image_px".into(),
            toml::Value::Array(vec![truth.pixel.x.into(), truth.pixel.y.into()]),
        );
    }
    std::fs::write(&path, toml::to_string(&doc).unwrap()).unwrap();
}

#[test]
fn the_weak_direction_is_written_and_the_check_warns_with_the_fix() {
    let truth = narrow_truth();
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate_session(&truth, &narrow_spec(3, 2.0)).unwrap();
    write_session(&sim, dir.path()).unwrap();
    given_centroids(dir.path(), &sim);
    let report = check(&dir.path().join("session.toml"));
    let layout: Vec<_> = report
        .findings
        .iter()
        .filter(|f| f.severity == Severity::Warning && f.message.contains("the targets alone"))
        .collect();
    assert!(
        !layout.is_empty(),
        "no layout warning: {:#?}",
        report.findings
    );
    let text = &layout
        .iter()
        .find(|f| f.message.contains("camera.z_mm") || f.message.contains("camera.focal_length_mm"))
        .unwrap_or_else(|| panic!("the dolly is not named: {layout:#?}"))
        .message;
    // The fix in numbers: layers farther apart than now (2 mm between
    // layers, 4 mm span), or marks.
    let needed: f64 = text
        .split("at least ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no distance in: {text}"));
    assert!(needed > 4.0, "{text}");
    assert!(text.contains("screen_point"), "{text}");
    println!("{text}");
    // Layers 150 mm apart determine it: no such warning.
    let wide = tempfile::tempdir().unwrap();
    let sim_wide = simulate_session(&truth, &narrow_spec(3, 150.0)).unwrap();
    write_session(&sim_wide, wide.path()).unwrap();
    given_centroids(wide.path(), &sim_wide);
    let report = check(&wide.path().join("session.toml"));
    assert!(
        !report
            .findings
            .iter()
            .any(|f| f.message.contains("the targets alone")),
        "{:#?}",
        report.findings
    );
    // The calibrated station's uncertainty file names the weak direction in
    // its comments, and stays a valid mfd-station-uncertainty/1.
    let cal = calibrate(&sim.input).unwrap();
    let out = tempfile::tempdir().unwrap();
    cal.write(out.path()).unwrap();
    let unc = std::fs::read_to_string(out.path().join("station_uncertainty.toml")).unwrap();
    assert!(unc.contains("weakly determined"), "{unc}");
    assert!(
        unc.lines()
            .any(|l| l.starts_with('#') && l.contains("camera.z_mm")),
        "{unc}"
    );
    let parsed: toml::Value = toml::from_str(&unc).unwrap();
    assert_eq!(parsed["format"].as_str(), Some("mfd-station-uncertainty/1"));
    let summary = cal.report.summary();
    assert!(summary.contains("weakly determined"), "{summary}");
}

#[test]
fn a_plate_on_the_calibrated_narrow_station_is_within_its_reported_uncertainty() {
    // Issue 35's done-when on its own layout (layers 20 mm apart, 75
    // targets, 0.08 px): a plate measured on the calibrated station within
    // 20 nm RMS and within 0.5–2× the error it reports. Per seed the
    // error is one draw of the station's error projected on the surfaces
    // (a few degrees of freedom carry it), so the ratio is judged pooled
    // over the seeds' four surfaces (RMS), each surface at most 2×. The
    // plate is measured with the camera binned 4 × 4 (the calibrated
    // geometry, 1/16 of the pixels: the full sensor's 700 000 paths take
    // minutes per seed here).
    let truth = narrow_truth();
    let mut ratios = Vec::new();
    for seed in [3, 4] {
        let sim = simulate_session(&truth, &narrow_spec(seed, 20.0)).unwrap();
        let cal = calibrate(&sim.input).unwrap();
        for (face, (error, reported)) in
            ["front", "back"]
                .into_iter()
                .zip(crate::calibrate_chain::plate_on_calibrated(
                    &sim.truth, &cal, 4,
                ))
        {
            println!("seed {seed} {face}: error {error:.2} nm, reported {reported:.2} nm");
            assert!(error <= 20.0, "seed {seed} {face}: {error:.2} nm");
            assert!(
                error <= 2.0 * reported,
                "seed {seed} {face}: {error:.2} / {reported:.2}"
            );
            ratios.push(error / reported);
        }
    }
    let rms = (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len() as f64).sqrt();
    println!(
        "RMS error / reported over {} surfaces: {rms:.2}",
        ratios.len()
    );
    // Issue 35's band, 0.5–2×: measured 0.87 (seeds 3, 4: 2.1–4.0 nm
    // against 3.2–3.6 reported). It was 0.39 while the valley's curvature
    // term put the long directions' bend into one another on their own
    // diagonal (σ(camera.z) 2.08 mm for a scatter of 1.31, see
    // `the_weak_directions_sigma_matches_its_scatter`) and while the plate
    // was traced on the station before the session drew its element's
    // in-plane offset.
    assert!((0.5..=2.0).contains(&rms), "RMS error/reported {rms:.2}");
}

#[test]
fn the_weak_directions_sigma_matches_its_scatter() {
    // The weak "dolly zoom" of the layout (layers 20 mm apart)
    // carries the plate's share of the calibration's error (focal length,
    // camera and screen heights: 270, 120 and 115 nm per σ on the plate
    // below), so its σ must be its scatter, not only cover it. Over 40
    // seeds the mean (error/σ)² of camera.z is χ²(40)/40 when the σ is
    // right: within [0.45, 1.84] with probability 0.998 (χ²(40) quantiles
    // 17.9 and 73.4 at 0.001 and 0.999). Measured 1.13 (1.06 before the
    // pairs' bends of `calibrate::valley`); 0.40 when the
    // valley's curvature term let its settling move along the other long
    // directions (σ(camera.z) 2.08 mm for a scatter of 1.31).
    //
    // The same seeds carry issue 35's line for the whole error vector: χ²
    // (k = 30) at p ≥ 0.001 in every seed, and its mean k ± 4 √(2k/N) =
    // 30 ± 4.9. Measured: mean 28.7, worst 53.3; with each long direction's
    // own bend only (`3 q qᵀ`), 19 of 40 seeds failed (median χ² 50.3).
    let truth = narrow_truth();
    let seeds = 100..140;
    let mut z2 = Vec::new();
    let mut chi2s = Vec::new();
    for seed in seeds.clone() {
        let sim = simulate_session(&truth, &narrow_spec(seed, 20.0)).unwrap();
        let cal = calibrate(&sim.input).unwrap();
        let (chi2, n, each) = chi2_of_errors(&sim, &cal);
        assert_eq!(n, 30, "the χ² bound below is for 30 parameters");
        chi2s.push((seed, chi2));
        let (_, z) = each
            .iter()
            .find(|(n, _)| n == "camera.z_mm")
            .expect("camera.z is estimated")
            .clone();
        z2.push(z);
    }
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    println!(
        "camera.z: mean (error/σ)² {mean:.3} over {} seeds",
        z2.len()
    );
    let mean_chi2 = chi2s.iter().map(|c| c.1).sum::<f64>() / chi2s.len() as f64;
    let (worst_seed, worst) = chi2s
        .iter()
        .copied()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap();
    println!("χ² of the errors: mean {mean_chi2:.1} over 30, worst {worst:.1} (seed {worst_seed})");
    assert!(
        worst < CHI2_30_AT_0_999,
        "seed {worst_seed}: χ² of the errors {worst:.1} over 30 (p < 0.001)"
    );
    let tol = 4.0 * (2.0 * 30.0 / chi2s.len() as f64).sqrt();
    assert!(
        (mean_chi2 - 30.0).abs() < tol,
        "mean χ² of the errors {mean_chi2:.1} against 30 ± {tol:.1}"
    );
    assert!(
        (17.9 / 40.0..=73.4 / 40.0).contains(&mean),
        "mean (error/σ)² of camera.z {mean:.3} over seeds {seeds:?}"
    );
}
