//! The camera by resection: a linear start by the direct linear transform
//! ([`super::dlt::dlt`]) from at least six world points and their
//! centroids, decomposed into position, rotation, focal length and
//! principal point; then the weighted least squares over those and the
//! distortion ([`super::adjust::adjust`] over the camera's degrees of
//! freedom against the targets alone).
//!
//! Hand-written: the decomposition is an RQ of a 3×3 over nalgebra's QR;
//! no crate in the stack does camera resection.

use nalgebra::{Matrix3, Matrix3x4, Point2, Point3, Rotation3, Vector3};

use super::adjust::{adjust, Adjusted};
use super::dlt::dlt;
use super::error::CalibrationError;
use super::input::CalibrationInput;
use super::params::{Param, State, STATION_DOFS};
use super::residuals::Blocks;
use crate::optics::station::{Camera, Distortion};

/// The fewest targets a DLT solves with (11 unknowns, 2 equations each).
pub const MIN_TARGETS: usize = 6;

/// The camera's degrees of freedom, in [`STATION_DOFS`] order, and its
/// aspect ratio where the nominal station declares one.
pub fn camera_params(nominal: &Camera) -> Vec<Param> {
    let mut params: Vec<Param> = STATION_DOFS
        .iter()
        .filter(|d| d.dof.name().starts_with("camera."))
        .map(|d| Param::Station(d.dof))
        .collect();
    if nominal.aspect_ratio.is_some() {
        params.push(Param::AspectRatio);
    }
    params
}

/// A pinhole read off a projection matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearCamera {
    /// Projection centre, world frame, mm.
    pub position_mm: Point3<f64>,
    /// Camera-to-world rotation.
    pub world_from_camera: Rotation3<f64>,
    /// Focal length, px (the mean of the two axes').
    pub focal_px: f64,
    /// `[fx, fy]`, px: the columns' and the rows' focal lengths.
    pub focal_px_xy: [f64; 2],
    /// Principal point, px (pixel-centre convention, as the pixels given).
    pub principal_point_px: Point2<f64>,
}

/// Position, rotation, focal length (px) and principal point of a
/// projection matrix (RQ of its left 3×3), with the points in front.
pub fn decompose(p: &Matrix3x4<f64>, world: &[Point3<f64>]) -> Option<LinearCamera> {
    let mut p = *p;
    let m: Matrix3<f64> = p.fixed_view::<3, 3>(0, 0).into();
    let centre = -(m.try_inverse()? * p.column(3));
    // Points in front: the third row's depth is positive for them.
    let depth = |pm: &Matrix3x4<f64>, x: &Point3<f64>| (pm * x.to_homogeneous())[2];
    if depth(&p, &world[0]) < 0.0 {
        p = -p;
    }
    let m: Matrix3<f64> = p.fixed_view::<3, 3>(0, 0).into();
    let flip = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let qr = (flip * m).transpose().qr();
    let (q, r) = (qr.q(), qr.r());
    let mut k = flip * r.transpose() * flip;
    let mut rot = flip * q.transpose();
    let signs = Matrix3::from_diagonal(&Vector3::from_fn(|i, _| k[(i, i)].signum()));
    k *= signs;
    rot = signs * rot;
    if rot.determinant() < 0.0 {
        return None;
    }
    k /= k[(2, 2)];
    let f = 0.5 * (k[(0, 0)] + k[(1, 1)]);
    let camera_from_world = Rotation3::from_matrix(&rot);
    Some(LinearCamera {
        position_mm: Point3::from(centre),
        world_from_camera: camera_from_world.inverse(),
        focal_px: f,
        focal_px_xy: [k[(0, 0)], k[(1, 1)]],
        principal_point_px: Point2::new(k[(0, 2)], k[(1, 2)]),
    })
}

/// The DLT camera from the targets at `state`'s world frame, with the
/// nominal's sensor and distortion (the values a held coefficient keeps);
/// `None` where the DLT fails.
pub fn linear_start(input: &CalibrationInput, state: &State) -> Option<Camera> {
    let world: Vec<Point3<f64>> = input
        .targets
        .iter()
        .map(|t| state.frame.to_world(&t.stage_mm))
        .collect();
    let pixels: Vec<Point2<f64>> = input.targets.iter().map(|t| t.pixel).collect();
    let p = dlt(&world, &pixels)?;
    let lin = decompose(&p, &world)?;
    let nominal = &state.station.camera;
    // A declared aspect ratio is estimated, so it starts from the DLT's;
    // square pixels keep the mean of the two axes' focal lengths.
    let [fx, fy] = lin.focal_px_xy;
    let (focal_px, aspect_ratio) = match nominal.aspect_ratio {
        Some(_) => (fx, Some(fy / fx)),
        None => (lin.focal_px, None),
    };
    let cam = Camera {
        position_mm: lin.position_mm,
        world_from_camera: lin.world_from_camera,
        focal_length_mm: focal_px * nominal.pixel_pitch_mm,
        principal_point_px: lin.principal_point_px,
        aspect_ratio,
        distortion: Some(nominal.distortion.unwrap_or(Distortion {
            k: [0.0; 3],
            p: [0.0; 2],
        })),
        ..nominal.clone()
    };
    (cam.focal_length_mm.is_finite() && cam.focal_length_mm > 0.0).then_some(cam)
}

/// The camera by resection from `state` (its frame held): the DLT start
/// where it reprojects the targets better than the nominal camera, then the
/// weighted least squares over the camera's degrees of freedom.
///
/// # Errors
/// [`CalibrationError::TooFew`] with fewer than six targets,
/// [`CalibrationError::Degenerate`] when they are coplanar, or the
/// adjustment's.
pub fn resect(input: &CalibrationInput, state: &State) -> Result<Adjusted, CalibrationError> {
    if input.targets.len() < MIN_TARGETS {
        return Err(CalibrationError::TooFew {
            entry: "target_point",
            found: input.targets.len(),
            needed: MIN_TARGETS,
        });
    }
    let world: Vec<Point3<f64>> = input
        .targets
        .iter()
        .map(|t| state.frame.to_world(&t.stage_mm))
        .collect();
    if coplanar(&world) {
        return Err(CalibrationError::Degenerate {
            entry: "target_point",
            problem: "lie in one plane: place targets at two or more heights".into(),
        });
    }
    let blocks = Blocks::TARGETS;
    let mut start = state.clone();
    if let Some(cam) = linear_start(input, state) {
        let dlt_state = State {
            station: crate::optics::station::Station {
                camera: cam,
                ..state.station.clone()
            },
            ..state.clone()
        };
        if reprojection_ss(input, &dlt_state) < reprojection_ss(input, state) {
            start = dlt_state;
        }
    }
    let params = camera_params(&state.station.camera);
    adjust(input, start, state, &params, blocks, "resection")
}

fn reprojection_ss(input: &CalibrationInput, state: &State) -> f64 {
    let ss: f64 = input
        .targets
        .iter()
        .map(|t| {
            state
                .station
                .camera
                .project(&state.frame.to_world(&t.stage_mm))
                .map_or(f64::INFINITY, |p| (p - t.pixel).norm_squared())
        })
        .sum();
    if ss.is_finite() {
        ss
    } else {
        f64::INFINITY
    }
}

/// Whether points lie within a micrometre of one plane (their scatter's
/// smallest principal axis).
fn coplanar(pts: &[Point3<f64>]) -> bool {
    let n = pts.len() as f64;
    let mean = pts.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = pts.iter().fold(Matrix3::zeros(), |a, p| {
        a + (p.coords - mean) * (p.coords - mean).transpose()
    }) / n;
    cov.symmetric_eigenvalues().min().max(0.0).sqrt() < 1e-3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dlt_recovers_an_exact_pinhole() {
        let mut station = crate::calibrate::simulate::example_truth().unwrap();
        station.camera.distortion = None;
        let cam = &station.camera;
        let world: Vec<Point3<f64>> = (0..24)
            .map(|k| {
                let f = f64::from(k);
                Point3::new(
                    -90.0 + 8.0 * f,
                    60.0 * (0.7 * f).sin(),
                    40.0 * f64::from(k % 3),
                )
            })
            .collect();
        let pixels: Vec<Point2<f64>> = world.iter().map(|p| cam.project(p).unwrap()).collect();
        let p = dlt(&world, &pixels).unwrap();
        let lin = decompose(&p, &world).unwrap();
        let (c, r, f_px, pp) = (
            lin.position_mm,
            lin.world_from_camera,
            lin.focal_px,
            lin.principal_point_px,
        );
        // Noise-free: the DLT is exact to rounding of a 12×12 eigenproblem.
        assert!(
            (c - cam.position_mm).norm() < 1e-6,
            "{c} vs {}",
            cam.position_mm
        );
        assert!((r.matrix() - cam.world_from_camera.matrix()).norm() < 1e-9);
        assert!((f_px - cam.focal_px()).abs() < 1e-6);
        assert!((pp - cam.principal_point_px).norm() < 1e-6);
        // fx ≠ fy: the two axes' focal lengths read apart, as OpenCV's.
        let mut wide = cam.clone();
        wide.aspect_ratio = Some(1.002);
        let pixels: Vec<Point2<f64>> = world.iter().map(|p| wide.project(p).unwrap()).collect();
        let lin = decompose(&dlt(&world, &pixels).unwrap(), &world).unwrap();
        let [fx, fy] = wide.focal_px_xy();
        assert!((lin.focal_px_xy[0] - fx).abs() < 1e-6 && (lin.focal_px_xy[1] - fy).abs() < 1e-6);
        let in_a_plane: Vec<Point3<f64>> =
            world.iter().map(|p| Point3::new(p.x, p.y, 5.0)).collect();
        assert!(coplanar(&in_a_plane));
        assert!(!coplanar(&world));
    }
}
