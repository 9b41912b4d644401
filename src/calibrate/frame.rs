//! The world frame a session defines (`calibration.md`, "The world frame a
//! session defines") and the element's pose in it.
//!
//! - The reference plane: the total-least-squares plane through the flat
//!   points (the stage noise is the same on every axis, so the distances
//!   are orthogonal), `+z` its normal on the stage's `+z` side.
//! - `x`: the stage's x axis projected onto the plane; `y = z × x`.
//! - Origin: the plane's point whose stage x, y are
//!   `element.center_stage_mm`. The element's centre is therefore the world
//!   origin, and a calibrated station's `aperture_center_mm` is `[0, 0]`.
//!
//! The plane's three parameters (stage z at the element's centre, and the
//! stage slopes dz/dx, dz/dy) come with their covariance from the stage
//! noise. The element's pose (interchange.md "Element pose": `p = c + R
//! (p' − c) + offset`, `R = R_y(ry) R_x(rx)`, `c` the world origin here) is
//! the plane through the element points in that frame; its covariance is
//! propagated to first order from every reading (flat and element points,
//! since the frame itself is estimated) through the exact computation, by
//! central differences at the scale of the stage noise. Without element
//! points the pose is zero, and its covariance is what the flat points
//! leave: the fitted reference plane's own error against the true flat.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::session::Session;
use super::spread::Spread;

/// Why no frame or pose could be formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// Too few points for a plane.
    #[error("`{entry}`: {count} points, at least 3 not on one line are needed for a plane")]
    TooFew {
        /// The entry kind (`flat_point`, `element_point`).
        entry: &'static str,
        /// How many were given.
        count: usize,
    },
    /// The plane stands (nearly) parallel to the stage's z axis.
    #[error(
        "`{entry}`: the plane through the points is {angle_deg:.1}° from the stage's xy plane; \
         the stage's +z must point roughly along the plane's normal (check the readings' axes)"
    )]
    Steep {
        /// The entry kind.
        entry: &'static str,
        /// Angle between the plane's normal and the stage z axis, degrees.
        angle_deg: f64,
    },
}

impl crate::outcome::Classify for FrameError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        // The session's flat points do not define the world frame.
        Some(Outcome::Input)
    }
}

/// A plane fitted to stage readings.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneFit {
    /// The plane's z at `(x0, y0)` (the frame's own reference point), mm.
    pub height_mm: f64,
    /// dz/dx and dz/dy of the plane in the frame it was fitted in.
    pub slope: [f64; 2],
    /// Covariance of `(height_mm, slope[0], slope[1])` from the stage noise
    /// (mm², mm, 1).
    pub covariance: Matrix3<f64>,
    /// Each point's signed distance from the plane (along the normal), µm.
    pub residuals_um: Vec<f64>,
    /// Σ (residual / stage σ)²; follows χ² with `dof` degrees of freedom when
    /// the points are on a plane and the noise is as stated.
    pub chi2: f64,
    /// N − 3.
    pub dof: usize,
    /// The plane's unit normal, on the frame's `+z` side.
    pub normal: Vector3<f64>,
}

impl PlaneFit {
    /// RMS of the residuals, µm.
    pub fn rms_um(&self) -> f64 {
        let n = self.residuals_um.len().max(1) as f64;
        (self.residuals_um.iter().map(|r| r * r).sum::<f64>() / n).sqrt()
    }

    /// The total-least-squares plane through `points`, described about
    /// `(x0, y0)`, with the covariance of its parameters for an isotropic
    /// noise of `std_mm` per axis.
    ///
    /// # Errors
    /// [`FrameError`] for fewer than 3 points or a plane within 60° of
    /// vertical (its slopes would not describe it).
    pub fn fit(
        entry: &'static str,
        points: &[Point3<f64>],
        x0: f64,
        y0: f64,
        std_mm: f64,
    ) -> Result<PlaneFit, FrameError> {
        if points.len() < 3 {
            return Err(FrameError::TooFew {
                entry,
                count: points.len(),
            });
        }
        let s = Spread::of(points);
        let mut n: Vector3<f64> = s.directions.column(2).into_owned();
        if n.z < 0.0 {
            n = -n;
        }
        let angle_deg = n.z.clamp(-1.0, 1.0).acos().to_degrees();
        // Beyond 60° the slopes exceed √3 and the stage's +z no longer tells
        // the plane's sides apart well: such a session has its axes wrong.
        if angle_deg > 60.0 {
            return Err(FrameError::Steep { entry, angle_deg });
        }
        let m = s.centroid;
        let slope = [-n.x / n.z, -n.y / n.z];
        let height_mm = m.z + slope[0] * (x0 - m.x) + slope[1] * (y0 - m.y);
        // z_i − (a + b dx + c dy) has variance σ² (1 + b² + c²) when every
        // axis carries σ: linear least squares in (a, b, c), whose
        // covariance is that variance times (AᵀA)⁻¹ (first order).
        let ata = points.iter().fold(Matrix3::zeros(), |acc, p| {
            let a = Vector3::new(1.0, p.x - x0, p.y - y0);
            acc + a * a.transpose()
        });
        let var = std_mm * std_mm * (1.0 + slope[0].powi(2) + slope[1].powi(2));
        let covariance = ata
            .try_inverse()
            .map_or(Matrix3::from_diagonal_element(f64::INFINITY), |inv| {
                inv * var
            });
        let residuals_um: Vec<f64> = points.iter().map(|p| n.dot(&(p - m)) * 1e3).collect();
        let chi2 = residuals_um
            .iter()
            .map(|r| (r * 1e-3 / std_mm).powi(2))
            .sum();
        Ok(PlaneFit {
            height_mm,
            slope,
            covariance,
            residuals_um,
            chi2,
            dof: points.len() - 3,
            normal: n,
        })
    }
}

/// The world frame of a session.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldFrame {
    /// Takes stage-frame points (mm) to the world frame (mm).
    pub world_from_stage: Isometry3<f64>,
    /// The reference plane in the stage frame, about the element's centre
    /// (`height_mm` is the stage z of the world origin).
    pub plane: PlaneFit,
    /// Stage x, y of the element's centre (the world origin), mm.
    pub center_stage_mm: [f64; 2],
    /// 1 σ of one stage reading, each axis, mm.
    pub stage_std_mm: f64,
}

impl WorldFrame {
    /// The frame from the flat points (stage frame, mm), the element's
    /// centre (stage x, y, mm) and the stage noise.
    ///
    /// # Errors
    /// [`FrameError`] when the flat points give no usable plane.
    pub fn from_flat_points(
        flat_stage_mm: &[Point3<f64>],
        center_stage_mm: [f64; 2],
        stage_std_mm: f64,
    ) -> Result<WorldFrame, FrameError> {
        let [cx, cy] = center_stage_mm;
        let plane = PlaneFit::fit("flat_point", flat_stage_mm, cx, cy, stage_std_mm)?;
        Ok(WorldFrame {
            world_from_stage: world_from_plane(&plane, center_stage_mm),
            plane,
            center_stage_mm,
            stage_std_mm,
        })
    }

    /// The frame of a validated session.
    ///
    /// # Errors
    /// [`FrameError::Steep`] when the flat points' plane is not roughly
    /// normal to the stage's z axis.
    pub fn of_session(session: &Session) -> Result<WorldFrame, FrameError> {
        WorldFrame::from_flat_points(
            &session.flat_points_mm,
            session.element.center_stage_mm,
            session.stage_std_mm,
        )
    }

    /// Takes world points to the stage frame.
    pub fn stage_from_world(&self) -> Isometry3<f64> {
        self.world_from_stage.inverse()
    }

    /// A stage reading in the world frame, mm.
    pub fn to_world(&self, p_stage: &Point3<f64>) -> Point3<f64> {
        self.world_from_stage * p_stage
    }

    /// A world point as a stage reading, mm.
    pub fn to_stage(&self, p_world: &Point3<f64>) -> Point3<f64> {
        self.world_from_stage.inverse_transform_point(p_world)
    }
}

/// The frame whose `z = 0` is `plane` (fitted about `center`), `x` the stage
/// x projected, origin above `center`.
fn world_from_plane(plane: &PlaneFit, center: [f64; 2]) -> Isometry3<f64> {
    let z = Vector3::new(-plane.slope[0], -plane.slope[1], 1.0).normalize();
    let x = (Vector3::x() - z * z.x).normalize();
    let y = z.cross(&x);
    // Rows x, y, z: world coordinates of a stage vector.
    let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let origin = Vector3::new(center[0], center[1], plane.height_mm);
    Isometry3::from_parts(Translation3::from(-(rotation * origin)), rotation)
}

/// Where the element's pose came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PoseSource {
    /// Fitted to this many element points.
    ElementPoints(usize),
    /// No element points: the element is taken to stand on the reference
    /// plane, and the covariance is the reference plane's own uncertainty.
    AssumedOnReferencePlane,
}

/// The element's pose in the world frame (interchange.md "Element pose"),
/// about the world origin (the element's centre).
#[derive(Debug, Clone, PartialEq)]
pub struct ElementPose {
    /// `offset_mm`: only z is determined by a plane; x and y are 0 since the
    /// world origin is the element's centre.
    pub offset_mm: Vector3<f64>,
    /// `tilt_deg = [rx, ry]`, `R = R_y(ry) R_x(rx)`.
    pub tilt_deg: [f64; 2],
    /// Covariance of `(offset_mm.z, tilt_deg[0], tilt_deg[1])` (mm², mm·deg, deg²).
    pub covariance: Matrix3<f64>,
    /// The element plane's fit in the world frame, where it was fitted.
    pub fit: Option<PlaneFit>,
    /// Where the pose came from.
    pub source: PoseSource,
}

impl ElementPose {
    /// 1 σ of `(offset_mm.z, tilt_deg[0], tilt_deg[1])`.
    pub fn std(&self) -> [f64; 3] {
        [0, 1, 2].map(|k| self.covariance[(k, k)].max(0.0).sqrt())
    }

    /// The pose of a session: fitted to its element points, or assumed on
    /// the reference plane without them.
    ///
    /// # Errors
    /// [`FrameError`] when the flat or element points give no usable plane.
    pub fn of_session(session: &Session) -> Result<ElementPose, FrameError> {
        element_pose(
            &session.flat_points_mm,
            &session.element_points_mm,
            session.element.center_stage_mm,
            session.stage_std_mm,
        )
    }
}

/// `(offset_z_mm, rx_deg, ry_deg)` of the plane `z = h + gx x + gy y`
/// (world frame, about the origin).
fn pose_of_plane(h: f64, gx: f64, gy: f64) -> [f64; 3] {
    // The front's normal is R ẑ = (cos rx sin ry, −sin rx, cos rx cos ry),
    // proportional to (−gx, −gy, 1).
    let ry = (-gx).atan();
    let rx = (gy * ry.cos()).atan();
    [h, rx.to_degrees(), ry.to_degrees()]
}

/// The element's pose from the flat points and the element points (both
/// stage frame, mm): fitted when there are element points, else assumed on
/// the reference plane with the reference plane's uncertainty.
///
/// # Errors
/// [`FrameError`] when either set gives no usable plane.
pub fn element_pose(
    flat_stage_mm: &[Point3<f64>],
    element_stage_mm: &[Point3<f64>],
    center_stage_mm: [f64; 2],
    stage_std_mm: f64,
) -> Result<ElementPose, FrameError> {
    let frame = WorldFrame::from_flat_points(flat_stage_mm, center_stage_mm, stage_std_mm)?;
    if element_stage_mm.is_empty() {
        return Ok(assumed_pose(&frame));
    }
    let nf = flat_stage_mm.len();
    let pose_of = |coords: &[f64]| -> Result<([f64; 3], PlaneFit), FrameError> {
        let pts = |range: std::ops::Range<usize>| -> Vec<Point3<f64>> {
            range
                .map(|k| Point3::new(coords[3 * k], coords[3 * k + 1], coords[3 * k + 2]))
                .collect()
        };
        let frame = WorldFrame::from_flat_points(&pts(0..nf), center_stage_mm, stage_std_mm)?;
        let world: Vec<Point3<f64>> = pts(nf..coords.len() / 3)
            .iter()
            .map(|p| frame.to_world(p))
            .collect();
        let fit = PlaneFit::fit("element_point", &world, 0.0, 0.0, stage_std_mm)?;
        Ok((
            pose_of_plane(fit.height_mm, fit.slope[0], fit.slope[1]),
            fit,
        ))
    };
    let x0: Vec<f64> = flat_stage_mm
        .iter()
        .chain(element_stage_mm)
        .flat_map(|p| [p.x, p.y, p.z])
        .collect();
    let (pose, fit) = pose_of(&x0)?;
    // Every reading carries σ on each axis, independently: C = σ² J Jᵀ.
    let j = central_jacobian(&x0, stage_std_mm, |x| {
        pose_of(x).map(|(p, _)| p).unwrap_or(pose)
    });
    let covariance =
        Matrix3::from_fn(|r, c| (j.row(r) * j.row(c).transpose())[(0, 0)]) * stage_std_mm.powi(2);
    Ok(ElementPose {
        offset_mm: Vector3::new(0.0, 0.0, pose[0]),
        tilt_deg: [pose[1], pose[2]],
        covariance,
        fit: Some(fit),
        source: PoseSource::ElementPoints(element_stage_mm.len()),
    })
}

/// Pose zero, with the covariance of the true flat's pose seen from the
/// fitted reference plane: the pose of the plane `p` in the frame of the
/// plane `p + δ`, to first order in δ, with δ ~ the plane fit's covariance.
fn assumed_pose(frame: &WorldFrame) -> ElementPose {
    let plane = &frame.plane;
    let c = frame.center_stage_mm;
    let truth = [plane.height_mm, plane.slope[0], plane.slope[1]];
    // Three points of the true (fitted-as-true) flat, stage frame.
    let on_truth: Vec<Point3<f64>> = [[0.0, 0.0], [50.0, 0.0], [0.0, 50.0]]
        .iter()
        .map(|[dx, dy]| {
            Point3::new(
                c[0] + dx,
                c[1] + dy,
                truth[0] + truth[1] * dx + truth[2] * dy,
            )
        })
        .collect();
    let seen_from = |p: &[f64]| -> [f64; 3] {
        let shifted = PlaneFit {
            height_mm: p[0],
            slope: [p[1], p[2]],
            ..plane.clone()
        };
        let f = world_from_plane(&shifted, c);
        let w: Vec<Point3<f64>> = on_truth.iter().map(|q| f * q).collect();
        // The plane through three exact points, in the world frame.
        let n = (w[1] - w[0]).cross(&(w[2] - w[0]));
        let (gx, gy) = (-n.x / n.z, -n.y / n.z);
        pose_of_plane(w[0].z + gx * (0.0 - w[0].x) + gy * (0.0 - w[0].y), gx, gy)
    };
    let steps: Vec<f64> = (0..3).map(|k| plane.covariance[(k, k)].sqrt()).collect();
    let j = central_jacobian_steps(&truth, &steps, seen_from);
    ElementPose {
        offset_mm: Vector3::zeros(),
        tilt_deg: [0.0, 0.0],
        covariance: {
            let j = Matrix3::from_fn(|r, c| j[(r, c)]);
            j * plane.covariance * j.transpose()
        },
        fit: None,
        source: PoseSource::AssumedOnReferencePlane,
    }
}

/// ∂f/∂x by central differences with step `h` on every coordinate.
fn central_jacobian(x0: &[f64], h: f64, f: impl Fn(&[f64]) -> [f64; 3]) -> nalgebra::DMatrix<f64> {
    central_jacobian_steps(x0, &vec![h; x0.len()], f)
}

/// ∂f/∂x by central differences with step `steps[k]` on coordinate `k`
/// (the noise scale, so that the linearisation is over the range the noise
/// explores; f is smooth, and the rounding error, ~1e-16 |x| / h, stays far
/// below the derivatives' size).
fn central_jacobian_steps(
    x0: &[f64],
    steps: &[f64],
    f: impl Fn(&[f64]) -> [f64; 3],
) -> nalgebra::DMatrix<f64> {
    let mut j = nalgebra::DMatrix::zeros(3, x0.len());
    let mut x = x0.to_vec();
    for k in 0..x0.len() {
        let h = if steps[k] > 0.0 { steps[k] } else { 1e-9 };
        x[k] = x0[k] + h;
        let up = f(&x);
        x[k] = x0[k] - h;
        let down = f(&x);
        x[k] = x0[k];
        for r in 0..3 {
            j[(r, k)] = (up[r] - down[r]) / (2.0 * h);
        }
    }
    j
}

#[cfg(test)]
#[path = "frame_tests.rs"]
mod tests;
