//! Known-truth tests of the world frame and the element pose: a stage
//! frame rotated and shifted against the world comes back, and the pose's
//! error against its reported covariance follows χ² over seeds.

use super::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

/// A stage tilted 2° about a skew axis and turned 25° about z, shifted by
/// [120, 80, 15] mm: the true `stage_from_world`.
fn stage_from_world() -> Isometry3<f64> {
    let tilt = Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(0.6, -0.8, 0.0)),
        2f64.to_radians(),
    );
    let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), 25f64.to_radians());
    Isometry3::from_parts(
        Translation3::new(120.0, 80.0, 15.0),
        UnitQuaternion::from_rotation_matrix(&(tilt * turn)),
    )
}

/// World points of a 4 × 4 grid over ±40 mm at height `z`.
fn grid(z: f64) -> Vec<Point3<f64>> {
    (0..16)
        .map(|k| {
            Point3::new(
                -40.0 + 80.0 * (k % 4) as f64 / 3.0,
                -40.0 + 80.0 * (k / 4) as f64 / 3.0,
                z,
            )
        })
        .collect()
}

fn noisy(points: &[Point3<f64>], std_mm: f64, rng: &mut Xoshiro256PlusPlus) -> Vec<Point3<f64>> {
    let n = Normal::new(0.0, std_mm).unwrap();
    points
        .iter()
        .map(|p| p + Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng)))
        .collect()
}

/// The element's front in the world for a pose: p = R p' + offset (c = 0).
fn posed(offset_z: f64, rx_deg: f64, ry_deg: f64) -> Vec<Point3<f64>> {
    let r = Rotation3::from_axis_angle(&Vector3::y_axis(), ry_deg.to_radians())
        * Rotation3::from_axis_angle(&Vector3::x_axis(), rx_deg.to_radians());
    grid(0.0)
        .iter()
        .map(|p| Point3::from(r * p.coords * 0.5 + Vector3::new(0.0, 0.0, offset_z)))
        .collect()
}

#[test]
fn a_rotated_shifted_stage_frame_comes_back() {
    let s_from_w = stage_from_world();
    let flat: Vec<_> = grid(0.0).iter().map(|p| s_from_w * p).collect();
    let origin = s_from_w * Point3::origin();
    let frame = WorldFrame::from_flat_points(&flat, [origin.x, origin.y], 1e-3).unwrap();
    // The flat lies at world z = 0 and the origin is where the session says.
    for p in &flat {
        assert!(frame.to_world(p).z.abs() < 1e-9, "{}", frame.to_world(p));
    }
    assert!(frame.to_world(&origin).coords.norm() < 1e-9);
    // The world z is the flat's normal, x the stage x projected: the truth
    // differs from the fitted frame only by a turn about z, which the
    // session's convention fixes (stage x has no world y component).
    let w_from_s = frame.world_from_stage;
    let diff = w_from_s * s_from_w;
    assert!((diff.rotation * Vector3::z() - Vector3::z()).norm() < 1e-12);
    let x_stage_in_world = w_from_s.rotation * Vector3::x();
    assert!(x_stage_in_world.y.abs() < 1e-12 && x_stage_in_world.x > 0.0);
    assert!((w_from_s.rotation * Vector3::z()).z > 0.0);
    for p in grid(7.0) {
        assert!((frame.to_world(&frame.to_stage(&p)) - p).norm() < 1e-9);
    }
    assert!(frame.plane.rms_um() < 1e-6);
}

/// Mean χ² of `errors` against `covs` over the seeds, with its own
/// standard error: for k degrees of freedom χ² has variance 2k, so the
/// mean of M draws has σ = √(2k/M).
fn mean_chi2(errors: &[Vector3<f64>], covs: &[Matrix3<f64>]) -> f64 {
    errors
        .iter()
        .zip(covs)
        .map(|(e, c)| (e.transpose() * c.try_inverse().unwrap() * e)[(0, 0)])
        .sum::<f64>()
        / errors.len() as f64
}

#[test]
fn plane_and_pose_errors_follow_their_covariance() {
    let s_from_w = stage_from_world();
    let origin = s_from_w * Point3::origin();
    let truth = [0.35, 0.6, -0.9];
    let std_mm = 1e-3;
    let seeds = 300;
    let (mut e_pose, mut c_pose, mut e_plane, mut c_plane) = (vec![], vec![], vec![], vec![]);
    // The true plane in the stage frame about the origin's stage x, y.
    let n_stage = s_from_w.rotation * Vector3::z();
    let true_plane = Vector3::new(origin.z, -n_stage.x / n_stage.z, -n_stage.y / n_stage.z);
    // The session's world frame turns `s_from_w`'s world about z (its x is
    // the stage x projected): the true pose is given in the session's
    // frame, built from the noise-free flat.
    let flat_exact: Vec<_> = grid(0.0).iter().map(|p| s_from_w * p).collect();
    let exact = WorldFrame::from_flat_points(&flat_exact, [origin.x, origin.y], std_mm).unwrap();
    for seed in 0..seeds {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let flat = noisy(
            &grid(0.0).iter().map(|p| s_from_w * p).collect::<Vec<_>>(),
            std_mm,
            &mut rng,
        );
        let elem: Vec<_> = posed(truth[0], truth[1], truth[2])
            .iter()
            .map(|p| exact.to_stage(p))
            .collect();
        let elem = noisy(&elem, std_mm, &mut rng);
        let pose = element_pose(&flat, &elem, [origin.x, origin.y], std_mm).unwrap();
        assert_eq!(pose.source, PoseSource::ElementPoints(16));
        e_pose.push(Vector3::new(
            pose.offset_mm.z - truth[0],
            pose.tilt_deg[0] - truth[1],
            pose.tilt_deg[1] - truth[2],
        ));
        c_pose.push(pose.covariance);
        let frame = WorldFrame::from_flat_points(&flat, [origin.x, origin.y], std_mm).unwrap();
        let p = &frame.plane;
        e_plane.push(Vector3::new(p.height_mm, p.slope[0], p.slope[1]) - true_plane);
        c_plane.push(p.covariance);
    }
    // 3 degrees of freedom: mean χ² = 3 ± √(6/300) = ±0.14; 4σ bounds.
    let tol = 4.0 * (6.0 / seeds as f64).sqrt();
    println!(
        "{seeds} seeds: mean χ² pose {:.3}, plane {:.3} (3 expected)",
        mean_chi2(&e_pose, &c_pose),
        mean_chi2(&e_plane, &c_plane)
    );
    for (what, m) in [
        ("pose", mean_chi2(&e_pose, &c_pose)),
        ("plane", mean_chi2(&e_plane, &c_plane)),
    ] {
        assert!(
            (m - 3.0).abs() < tol,
            "{what}: mean χ² {m:.3}, expected 3 ± {tol:.2}"
        );
    }
}

#[test]
fn without_element_points_the_pose_is_zero_with_the_planes_uncertainty() {
    let s_from_w = stage_from_world();
    let origin = s_from_w * Point3::origin();
    let std_mm = 2e-3;
    let seeds = 300;
    let (mut errors, mut covs) = (vec![], vec![]);
    for seed in 0..seeds {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1000 + seed);
        let flat = noisy(
            &grid(0.0).iter().map(|p| s_from_w * p).collect::<Vec<_>>(),
            std_mm,
            &mut rng,
        );
        let pose = element_pose(&flat, &[], [origin.x, origin.y], std_mm).unwrap();
        assert_eq!(pose.source, PoseSource::AssumedOnReferencePlane);
        assert_eq!(
            (pose.offset_mm, pose.tilt_deg),
            (Vector3::zeros(), [0.0, 0.0])
        );
        // The element truly stands on the true flat: its pose in the fitted
        // frame, from noise-free element points on the true flat.
        let exact: Vec<_> = posed(0.0, 0.0, 0.0).iter().map(|p| s_from_w * p).collect();
        let frame = WorldFrame::from_flat_points(&flat, [origin.x, origin.y], std_mm).unwrap();
        let w: Vec<_> = exact.iter().map(|p| frame.to_world(p)).collect();
        let fit = PlaneFit::fit("element_point", &w, 0.0, 0.0, std_mm).unwrap();
        let t = pose_of_plane(fit.height_mm, fit.slope[0], fit.slope[1]);
        errors.push(-Vector3::from(t));
        covs.push(pose.covariance);
    }
    let tol = 4.0 * (6.0 / seeds as f64).sqrt();
    let m = mean_chi2(&errors, &covs);
    println!("{seeds} seeds, no element points: mean χ² {m:.3} (3 expected)");
    assert!(
        (m - 3.0).abs() < tol,
        "mean χ² {m:.3}, expected 3 ± {tol:.2}"
    );
}

#[test]
fn a_plane_of_known_pose_gives_that_pose() {
    // Noise-free: interchange.md's R = R_y(ry) R_x(rx) round trip.
    let pts = posed(0.2, 1.5, -2.5);
    let fit = PlaneFit::fit("element_point", &pts, 0.0, 0.0, 1e-3).unwrap();
    let p = pose_of_plane(fit.height_mm, fit.slope[0], fit.slope[1]);
    for (a, b) in p.iter().zip([0.2, 1.5, -2.5]) {
        assert!((a - b).abs() < 1e-10, "{p:?}");
    }
}

#[test]
fn a_vertical_plane_is_refused() {
    let pts: Vec<_> = grid(0.0)
        .iter()
        .map(|p| Point3::new(p.z, p.x, p.y))
        .collect();
    let err = WorldFrame::from_flat_points(&pts, [0.0, 0.0], 1e-3).unwrap_err();
    assert!(matches!(err, FrameError::Steep { .. }), "{err}");
}
