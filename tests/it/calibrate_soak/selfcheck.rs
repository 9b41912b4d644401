//! The generator checked against itself and against mfd's reading of the
//! same spec: its stage frame is the world frame `calibration.md` defines
//! (as mfd's `WorldFrame` computes it), and a session without noise whose
//! nominal station is the truth calibrates back to the truth, to the
//! precision of its (tiny) stated noise. A disagreement between the two
//! implementations of the spec shows here first, before any statistics.

use mfd::calibrate::calibration::calibrate;
use mfd::calibrate::params::{difference, Param, State};
use nalgebra::{Point3, Vector3};

use super::draw::Draw;
use super::gen::Session;

#[test]
fn the_stage_frame_is_the_specs_world_frame() {
    for seed in 0..20 {
        let s = Session::new(&Draw::new(seed));
        let wf = s.stage.world_frame();
        let m = wf.stage_from_world();
        // Both are rotations built in f64 from the same plane: rounding.
        assert!((m.matrix() - s.stage.m).norm() < 1e-12, "seed {seed}");
        let p = Point3::new(12.0, -40.0, 300.0);
        assert!(
            (wf.to_world(&s.stage.stage(&p)) - p).norm() < 1e-10,
            "seed {seed}"
        );
        // The spec: world x is the stage's x projected onto the plane.
        let stage_x_in_world = s.stage.m.transpose() * Vector3::x();
        assert!(stage_x_in_world.y.abs() < 1e-15 && stage_x_in_world.x > 0.0);
    }
}

#[test]
fn a_noise_free_session_from_the_truth_calibrates_to_the_truth() {
    // Readings without noise, stated to 1e-5 px and 1e-6 mm, and a nominal
    // station equal to the truth but for its distortion (none): the data
    // determine every parameter they see 1e4 times better than a real
    // session, and the adjustment stops within a few hundredths of those
    // σ, so the flat's screen points must come back to 1e-4 screen px; any
    // difference in how the two implementations read the spec would leave
    // residuals far above the stated noise (χ² per reading ≫ 1).
    for seed in [1, 2, 3, 4, 5, 6] {
        let mut draw = Draw::new(seed);
        draw.noise_free = true;
        draw.nominal_scale = 0.0;
        draw.centroid_std_px = 1e-5;
        draw.flat_std_px = 1e-5;
        draw.stage_std_mm = 1e-6;
        let s = Session::new(&draw);
        let cal = calibrate(&s.input).unwrap_or_else(|e| panic!("seed {seed}: {e}\n{draw:?}"));
        let joint = cal.report.steps.last().expect("a joint step");
        let per_reading = joint.chi2 / joint.dof.max(1) as f64;
        let params: Vec<Param> = cal
            .names
            .iter()
            .filter_map(|n| Param::from_name(n))
            .collect();
        let truth = State {
            frame: s.stage.world_frame(),
            station: s.truth.clone(),
        };
        let est = State {
            frame: cal.frame,
            station: cal.station.clone(),
        };
        let e = difference(&truth, &est, &params);
        let worst = cal
            .names
            .iter()
            .zip(&e)
            .map(|(n, v)| format!("{n} {v:.2e}"))
            .collect::<Vec<_>>()
            .join(", ");
        let flat = s
            .truth_flat_points()
            .iter()
            .map(|([i, j], uv)| {
                cal.flat_screen_point(*i, *j)
                    .map_or(f64::INFINITY, |(p, _)| (p - uv).norm())
            })
            .fold(0.0, f64::max);
        eprintln!("seed {seed}: χ²/dof {per_reading:.3e}, flat {flat:.2e} px; {worst}");
        assert!(
            per_reading < 1.0,
            "seed {seed}: χ²/dof {per_reading}: {draw:?}"
        );
        assert!(
            flat < 1e-4,
            "seed {seed}: flat points {flat} px off: {draw:?}"
        );
    }
}
