//! The calibration on simulated sessions (`mfd::calibrate::simulate`): the truth
//! comes back within the reported covariance (χ² over many seeds), the
//! calibrated station's flat-reflected screen points match the truth's over
//! the sensor, what the data cannot determine is held and reported, and bad
//! sessions are refused with errors naming the entry.

use mfd::calibrate::calibration::{calibrate, Calibration};
use mfd::calibrate::error::CalibrationError;
use mfd::calibrate::params::{difference, Param, State};
use mfd::calibrate::simulate::{
    example_truth, flat_truth, simulate_session, SessionSpec, SimulatedSession,
};
use mfd::optics::station::Station;
use nalgebra::{DMatrix, DVector};

fn session(seed: u64, spec: SessionSpec) -> SimulatedSession {
    let truth = example_truth().unwrap();
    simulate_session(&truth, &SessionSpec { seed, ..spec }).unwrap()
}

/// `(estimate − truth)ᵀ C⁻¹ (estimate − truth)` over every parameter the
/// calibration reports, their number, and each one's `(error / σ)²`.
pub(crate) fn chi2_of_errors(
    sim: &SimulatedSession,
    cal: &Calibration,
) -> (f64, usize, Vec<(String, f64)>) {
    let params: Vec<Param> = cal
        .names
        .iter()
        .map(|n| Param::from_name(n).unwrap())
        .collect();
    let truth = State {
        frame: sim.frame,
        station: sim.truth.clone(),
    };
    let est = State {
        frame: cal.frame,
        station: cal.station.clone(),
    };
    let e = DVector::from_vec(difference(&truth, &est, &params));
    let c: &DMatrix<f64> = &cal.covariance;
    let chol = c
        .clone()
        .cholesky()
        .expect("the reported covariance is positive definite");
    let each = (0..params.len())
        .map(|k| (cal.names[k].clone(), e[k] * e[k] / c[(k, k)]))
        .collect();
    (e.dot(&chol.solve(&e)), params.len(), each)
}

#[test]
fn errors_follow_the_reported_covariance_over_many_seeds() {
    // Each seed's χ² of the errors is χ²(k) when the covariance is right
    // (held parameters are off by draws from their prior ranges, so they
    // count too): the mean of N seeds is k ± √(2k/N). Four of those σ
    // bound it; a covariance 20 % too small or too large (χ² off by 25 %
    // or 30 % of k ≈ 29, i.e. by 7 or more) fails.
    //
    // Each parameter alone: its (error / σ)² is χ²(1), whose mean over N
    // seeds is 1 ± √(2/N) (0.20 at N = 48); with 29 parameters tested at
    // once, 4.5 of those σ keep a false alarm below 1e-4 and still catch a
    // σ off by a factor of 1.7 either way (a mean of 3 or 0.35).
    let seeds = 48;
    let mut sum = 0.0;
    let mut k = 0;
    let mut each: std::collections::BTreeMap<String, (f64, usize)> = Default::default();
    for seed in 0..seeds {
        let sim = session(seed, SessionSpec::default());
        let cal = calibrate(&sim.input).unwrap();
        let (chi2, n, per) = chi2_of_errors(&sim, &cal);
        sum += chi2;
        k = n;
        for (name, z2) in per {
            let e = each.entry(name).or_insert((0.0, 0));
            e.0 += z2;
            e.1 += 1;
        }
    }
    let mean = sum / seeds as f64;
    let tol = 4.0 * (2.0 * k as f64 / seeds as f64).sqrt();
    println!("mean χ² {mean:.2} over {seeds} seeds, {k} parameters (tolerance ±{tol:.2})");
    assert!(
        (mean - k as f64).abs() < tol,
        "mean χ² {mean} against {k} ± {tol}"
    );
    for (name, (z2, n)) in &each {
        let m = z2 / *n as f64;
        let tol = 4.5 * (2.0 / *n as f64).sqrt();
        println!("{name:<24} mean (error/σ)² {m:.2} over {n} seeds");
        assert!(
            (m - 1.0).abs() < tol,
            "{name}: mean (error/σ)² {m} over {n} seeds (±{tol:.2})"
        );
    }
}

#[test]
fn flat_screen_points_match_the_truth_over_the_sensor() {
    // The bound: 0.05 screen px with 1 µm stage noise, for the rays
    // the flat reflects, over the sensor (a grid of 1 in 23 pixels, every
    // pixel whose reflection off the reference plane reaches the screen).
    // Where the ray meets the Ø 150 mm flat the flat's own fringe map pins
    // it (worst 0.012 px); beyond it (the sensor's rim, 120–130 mm out) the
    // camera model is extrapolated from the targets, and there the reported
    // σ is largest: 0.022 px (both axes together, 0.016 each) at the top
    // edge, nearly all of it the camera's principal point and rotation,
    // which trade against each other. 0.05 px is 3.2 of those σ per axis,
    // exceeded by a 2-D Gaussian error with probability e^(−3.2²/2) =
    // 0.7 % at that pixel, and the rim's pixels err together: a session
    // whose worst rim pixel exceeds the bound is a few-percent event
    // (measured: 2 of 64 other seeds, 1000–1063, up to 0.056 px). The
    // targets at the inset sensor's edges (`make::target_layout`) made it
    // so; with the earlier layout (cell centres, the outermost 4–12 % in
    // from the edges) these seeds gave 0.079.
    // So the bound is asserted on these 16 seeds, and the honesty of the
    // reported σ over every pixel: per seed, the pixels' mean of eᵀC⁻¹e has
    // mean 2 and a variance at most a single χ²(2)'s, 4 (an average of
    // correlated terms), so over N seeds it is 2 ± 2/√N at worst; four of
    // those bound it.
    let seeds = 16;
    let flat_radius_mm = SessionSpec::default().flat_radius_mm;
    let (mut normalised, mut worst_on_flat, mut worst_beyond) = (0.0, 0.0_f64, 0.0_f64);
    for seed in 100..100 + seeds {
        let sim = session(seed, SessionSpec::default());
        let cal = calibrate(&sim.input).unwrap();
        let truth = &sim.truth;
        let (mut sum, mut n, mut on_flat) = (0.0, 0, 0);
        for j in (0..truth.camera.height).step_by(23) {
            for i in (0..truth.camera.width).step_by(23) {
                let Some((t, hit)) = flat_truth(truth, i, j) else {
                    continue;
                };
                let (e, c) = cal
                    .flat_screen_point(i, j)
                    .expect("the calibrated ray reaches the screen");
                let d = e - t;
                if hit.coords.xy().norm() <= flat_radius_mm {
                    worst_on_flat = worst_on_flat.max(d.norm());
                    on_flat += 1;
                } else {
                    worst_beyond = worst_beyond.max(d.norm());
                }
                sum += d.dot(&(c.try_inverse().unwrap() * d));
                n += 1;
            }
        }
        assert!(on_flat > 500, "seed {seed}: {on_flat} pixels see the flat");
        normalised += sum / n as f64;
    }
    let mean = normalised / seeds as f64;
    println!(
        "worst {worst_on_flat:.4} screen px on the flat, {worst_beyond:.4} beyond it; \
         mean eᵀC⁻¹e {mean:.3} over {seeds} seeds"
    );
    assert!(
        worst_on_flat < 0.05,
        "{worst_on_flat} screen px on the flat"
    );
    assert!(
        worst_beyond < 0.05,
        "{worst_beyond} screen px beyond the flat"
    );
    assert!(
        (mean - 2.0).abs() < 4.0 * 2.0 / (seeds as f64).sqrt(),
        "{mean}"
    );
}

fn held(cal: &Calibration) -> Vec<String> {
    let joint = cal.report.steps.iter().find(|s| s.name == "joint").unwrap();
    joint
        .selection
        .held
        .iter()
        .map(|h| h.name.clone())
        .collect()
}

#[test]
fn what_the_data_cannot_determine_is_held_and_reported() {
    let sim = session(7, SessionSpec::default());
    let cal = calibrate(&sim.input).unwrap();
    let held = held(&cal);
    // Points on a plane say nothing of the element's in-plane position; the
    // flat's rays are a central projection from the camera's mirror image,
    // where a screen scaled about it looks the same (only the cover glass
    // breaks that, far below the pitch's datasheet precision).
    for name in ["element.x_mm", "element.y_mm", "screen.pixel_pitch_mm"] {
        assert!(
            held.contains(&name.to_string()),
            "{name} not held: {held:?}"
        );
    }
    // The cover glass shifts a landing by t (tan θ − tan θ_g) ≈ t (1 − 1/n)
    // tan θ: to first order in θ a move of the screen along its normal; at
    // the flat's ≤ 15° the rest is far below its 0.1 mm prior's effect.
    assert!(
        held.contains(&"screen.cover_glass.thickness_mm".to_string()),
        "{held:?}"
    );
    // k3 moves a corner of this sensor (r² ≈ 0.036) by k3 r⁷ F ≈ 0.04 px
    // per unit: below the 0.05 px centroids at the 0.5 prior range.
    assert!(held.contains(&"camera.k3".to_string()), "{held:?}");
    let summary = cal.report.summary();
    assert!(summary.contains("held camera.k3"), "{summary}");
    assert!(summary.contains("condition"), "{summary}");
    // Estimated parameters are not held.
    let joint = cal.report.steps.iter().find(|s| s.name == "joint").unwrap();
    assert!(joint.selection.estimated.contains(&"camera.k1".to_string()));
    assert!(joint
        .selection
        .estimated
        .contains(&"element.rx_deg".to_string()));
    for step in &cal.report.steps {
        // χ²/dof of a correct model with the stated noise: 1 ± √(2/dof),
        // dof ≥ 100 here; five of those σ bound it.
        let tol = 5.0 * (2.0 / step.dof as f64).sqrt();
        assert!(
            (step.chi2_per_dof - 1.0).abs() < tol,
            "{}: {}",
            step.name,
            step.chi2_per_dof
        );
    }
}

#[test]
fn without_element_points_the_pose_is_held_and_said_so() {
    let mut truth = example_truth().unwrap();
    truth.element.pose.offset_mm.z = 0.0;
    truth.element.pose.tilt_deg = [0.0; 2];
    let spec = SessionSpec {
        element_points: 0,
        seed: 3,
        ..SessionSpec::default()
    };
    let sim = simulate_session(&truth, &spec).unwrap();
    let cal = calibrate(&sim.input).unwrap();
    let held = held(&cal);
    for name in ["element.z_mm", "element.rx_deg", "element.ry_deg"] {
        assert!(held.contains(&name.to_string()), "{name}: {held:?}");
    }
    assert!(cal
        .report
        .notes
        .iter()
        .any(|n| n.contains("no element points")));
}

#[test]
fn bad_sessions_name_the_entry() {
    let sim = session(5, SessionSpec::default());
    let mut few = sim.input.clone();
    few.flat_points_stage_mm.truncate(2);
    assert!(matches!(
        calibrate(&few),
        Err(CalibrationError::TooFew {
            entry: "flat_point",
            found: 2,
            ..
        })
    ));
    let mut line = sim.input.clone();
    for (k, p) in line.flat_points_stage_mm.iter_mut().enumerate() {
        *p = nalgebra::Vector3::new(10.0 * k as f64, 5.0 * k as f64, 12.0);
    }
    assert!(matches!(
        calibrate(&line),
        Err(CalibrationError::Degenerate {
            entry: "flat_point",
            ..
        })
    ));
    let mut flat_targets = sim.input.clone();
    for t in &mut flat_targets.targets {
        t.stage_mm.z = sim.input.targets[0].stage_mm.z;
    }
    let err = calibrate(&flat_targets).unwrap_err();
    assert!(
        matches!(
            err,
            CalibrationError::Degenerate {
                entry: "target_point",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("two or more heights"));
    let mut bad_cov = sim.input.clone();
    bad_cov.flat_screen[3].screen_cov_px2 = nalgebra::Matrix2::zeros();
    assert!(matches!(
        calibrate(&bad_cov),
        Err(CalibrationError::BadCovariance {
            entry: "reference_flat",
            index: 3
        })
    ));
    let mut five = sim.input.clone();
    five.targets.truncate(5);
    assert!(matches!(
        calibrate(&five),
        Err(CalibrationError::TooFew {
            entry: "target_point",
            found: 5,
            needed: 6
        })
    ));
}

#[test]
fn a_calibration_writes_the_three_files() {
    let sim = session(9, SessionSpec::default());
    let cal = calibrate(&sim.input).unwrap();
    let dir = tempfile::tempdir().unwrap();
    cal.write(dir.path()).unwrap();
    let station = Station::load(&dir.path().join("station.toml")).unwrap();
    assert_eq!(station, cal.station);
    let text = std::fs::read_to_string(dir.path().join("station.toml")).unwrap();
    assert!(text.contains("mfd-station/2"));
    let path = dir.path().join("station_uncertainty.toml");
    // The lead's reader accepts it (symmetry, positive semi-definiteness).
    let read = mfd::optics::station::StationUncertainty::load(&path).unwrap();
    assert_eq!(read.correlated, 26);
    assert!(read.std_of(mfd::optics::station::Dof::K3) > 0.0);
    let unc: toml::Value = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(unc["format"].as_str(), Some("mfd-station-uncertainty/1"));
    let names = unc["covariance"]["names"].as_array().unwrap();
    assert!(names
        .iter()
        .all(|n| !n.as_str().unwrap().starts_with("frame.")));
    assert_eq!(
        unc["covariance"]["matrix"].as_array().unwrap().len(),
        names.len()
    );
    assert!(unc["std"]["element.thickness_mm"].as_float().unwrap() > 0.0);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).unwrap())
            .unwrap();
    assert_eq!(report["steps"].as_array().unwrap().len(), 3);
}
