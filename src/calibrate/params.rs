//! The adjustment's unknowns: the world frame's plane (3 numbers, in the
//! stage frame) and the station's degrees of freedom of
//! `mfd-station-uncertainty/1`, each a small change applied to the station
//! exactly as `interchange.md`'s table says. A step of the adjustment is a
//! vector of such changes; the covariance it reports is in the same
//! coordinates, so it is the station uncertainty file's covariance as it is.

use nalgebra::{Point3, Rotation3, Vector3};

use crate::optics::station::{Distortion, Dof, Station};

/// One unknown of the adjustment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Param {
    /// The flat plane's stage z at the element's centre, mm.
    PlaneHeight,
    /// The flat plane's slope `dz/dx` in the stage frame.
    PlaneSlopeX,
    /// The flat plane's slope `dz/dy` in the stage frame.
    PlaneSlopeY,
    /// A station degree of freedom of `mfd-station-uncertainty/1`.
    Station(Dof),
    /// The screen's cover-glass thickness, mm: estimated where the flat's
    /// rays determine it, but not a degree of freedom of the uncertainty
    /// file (its covariance is marginalised out there, like the plane's).
    CoverGlassThickness,
    /// The camera's `fy / fx` (proposal `docs/proposals/aspect.md`):
    /// estimated where the nominal station declares it, and, like the cover
    /// glass, not a degree of freedom of the uncertainty file.
    AspectRatio,
}

/// What the adjustment knows of a station degree of freedom before any
/// data: the finite-difference step of its Jacobian column (small against
/// any σ a session reaches, large against the residuals' rounding) and the
/// range the nominal station may be off by. A parameter whose marginal σ
/// from the data is not below its prior range is held at its nominal value
/// with that range as its σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DofPrior {
    /// The degree of freedom.
    pub dof: Dof,
    /// Central-difference step, in the DOF's unit.
    pub step: f64,
    /// 1 σ the nominal station may be off by, in the DOF's unit.
    pub prior_std: f64,
}

const fn dof(dof: Dof, step: f64, prior_std: f64) -> DofPrior {
    DofPrior {
        dof,
        step,
        prior_std,
    }
}

/// The station degrees of freedom a calibration may estimate (all of
/// `mfd-station-uncertainty/1` but the element's thickness and index, which
/// the session measures and gives). Prior ranges: a station assembled to
/// drawings is off by millimetres and tenths of a degree (10 mm and 2° are
/// generous bounds); a lens's focal length by well under a millimetre, its
/// principal point by tens of pixels, its distortion coefficients by their
/// own size on common lenses (0.5 radial, 0.01 tangential). The screen's
/// pitch is a lithographic datasheet value, 1e-4 of 0.27 mm. The element's
/// in-plane position is where the operator centred the PSM on it (0.1 mm);
/// without element points its height and tilts are what placing it where
/// the flat stood leaves open (0.05 mm, 0.05°).
pub const STATION_DOFS: [DofPrior; 26] = [
    dof(Dof::CameraX, 1e-4, 10.0),
    dof(Dof::CameraY, 1e-4, 10.0),
    dof(Dof::CameraZ, 1e-4, 10.0),
    dof(Dof::CameraRx, 1e-5, 2.0),
    dof(Dof::CameraRy, 1e-5, 2.0),
    dof(Dof::CameraRz, 1e-5, 2.0),
    dof(Dof::FocalLength, 1e-5, 1.0),
    dof(Dof::Cx, 1e-3, 50.0),
    dof(Dof::Cy, 1e-3, 50.0),
    dof(Dof::K1, 1e-6, 0.5),
    dof(Dof::K2, 1e-6, 0.5),
    dof(Dof::K3, 1e-6, 0.5),
    dof(Dof::P1, 1e-7, 0.01),
    dof(Dof::P2, 1e-7, 0.01),
    dof(Dof::ScreenX, 1e-4, 10.0),
    dof(Dof::ScreenY, 1e-4, 10.0),
    dof(Dof::ScreenZ, 1e-4, 10.0),
    dof(Dof::ScreenRx, 1e-5, 2.0),
    dof(Dof::ScreenRy, 1e-5, 2.0),
    dof(Dof::ScreenRz, 1e-5, 2.0),
    dof(Dof::ScreenPitch, 1e-7, 2.7e-5),
    dof(Dof::ElementX, 1e-4, 0.1),
    dof(Dof::ElementY, 1e-4, 0.1),
    dof(Dof::ElementZ, 1e-5, 0.05),
    dof(Dof::ElementRx, 1e-6, 0.05),
    dof(Dof::ElementRy, 1e-6, 0.05),
];

/// Finite-difference steps of the plane's parameters: height (mm) and slopes.
const PLANE_STEPS: [f64; 3] = [1e-5, 1e-8, 1e-8];

/// The cover glass's thickness: difference step and prior range, mm (a
/// display's datasheet gives its front glass to a tenth of a millimetre).
const COVER_GLASS_STEP_MM: f64 = 1e-5;
/// See [`COVER_GLASS_STEP_MM`].
pub const COVER_GLASS_PRIOR_MM: f64 = 0.1;

/// The aspect ratio's difference step: 1e-6 of fx moves a sensor's corner
/// pixel (≤ 3000 px off centre) by ≤ 3e-3 px, far above the residuals'
/// rounding and far below any σ a session reaches (the focal length's
/// step is 6e-7 of a 16 mm lens).
const ASPECT_STEP: f64 = 1e-6;
/// The range a declared aspect ratio may be off by: a datasheet's square
/// pixels or an earlier calibration, to 1 % (OpenCSP's cameras differ from
/// square by 0.1 %).
pub const ASPECT_PRIOR: f64 = 0.01;

/// The prior of a station DOF (`None` for the thickness and the index,
/// which a calibration takes as given).
pub fn prior(dof: Dof) -> Option<&'static DofPrior> {
    STATION_DOFS.iter().find(|d| d.dof == dof)
}

impl Param {
    /// The name in reports (the station DOFs' own; `frame.*` for the plane).
    pub fn name(&self) -> &'static str {
        match self {
            Param::PlaneHeight => "frame.height_mm",
            Param::PlaneSlopeX => "frame.slope_x",
            Param::PlaneSlopeY => "frame.slope_y",
            Param::Station(d) => d.name(),
            Param::CoverGlassThickness => "screen.cover_glass.thickness_mm",
            Param::AspectRatio => "camera.aspect_ratio",
        }
    }

    /// The parameter of a report name ([`Param::name`]); `None` for a name
    /// the adjustment does not know.
    pub fn from_name(name: &str) -> Option<Param> {
        match name {
            "frame.height_mm" => Some(Param::PlaneHeight),
            "frame.slope_x" => Some(Param::PlaneSlopeX),
            "frame.slope_y" => Some(Param::PlaneSlopeY),
            "screen.cover_glass.thickness_mm" => Some(Param::CoverGlassThickness),
            "camera.aspect_ratio" => Some(Param::AspectRatio),
            _ => Dof::parse(name)
                .and_then(prior)
                .map(|d| Param::Station(d.dof)),
        }
    }

    /// The central-difference step of its Jacobian column.
    pub fn step(&self) -> f64 {
        match self {
            Param::PlaneHeight => PLANE_STEPS[0],
            Param::PlaneSlopeX => PLANE_STEPS[1],
            Param::PlaneSlopeY => PLANE_STEPS[2],
            Param::Station(d) => prior(*d).map_or(1e-6, |p| p.step),
            Param::CoverGlassThickness => COVER_GLASS_STEP_MM,
            Param::AspectRatio => ASPECT_STEP,
        }
    }

    /// The 1 σ it is held with when the data do not determine it; the
    /// plane is always determined by the flat points (`None`).
    pub fn prior_std(&self) -> Option<f64> {
        match self {
            Param::Station(d) => prior(*d).map(|p| p.prior_std),
            Param::CoverGlassThickness => Some(COVER_GLASS_PRIOR_MM),
            Param::AspectRatio => Some(ASPECT_PRIOR),
            _ => None,
        }
    }
}

/// The world frame a session defines (`calibration.md`), from the plane
/// through the flat points `z = height + sx (x − cx) + sy (y − cy)` in the
/// stage frame and the element's centre `(cx, cy)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldFrame {
    /// `[height_mm, slope_x, slope_y]` of the plane, stage frame.
    pub plane: [f64; 3],
    /// Stage x, y of the element's centre, mm.
    pub center_stage_mm: [f64; 2],
}

impl WorldFrame {
    /// Rotation whose columns are the world axes in stage coordinates:
    /// `z` the plane's normal on the stage's `+z` side, `x` the stage's x
    /// projected onto the plane, `y = z × x`.
    pub fn stage_from_world(&self) -> Rotation3<f64> {
        let [_, sx, sy] = self.plane;
        let z = Vector3::new(-sx, -sy, 1.0).normalize();
        let x = (Vector3::x() - z.x * z).normalize();
        let y = z.cross(&x);
        Rotation3::from_basis_unchecked(&[x, y, z])
    }

    /// The world origin in the stage frame.
    pub fn origin_stage_mm(&self) -> Vector3<f64> {
        let [cx, cy] = self.center_stage_mm;
        Vector3::new(cx, cy, self.plane[0])
    }

    /// World position of a stage reading.
    pub fn to_world(&self, stage_mm: &Vector3<f64>) -> Point3<f64> {
        Point3::from(self.stage_from_world().inverse() * (stage_mm - self.origin_stage_mm()))
    }

    /// Stage reading of a world position.
    pub fn to_stage(&self, world: &Point3<f64>) -> Vector3<f64> {
        self.stage_from_world() * world.coords + self.origin_stage_mm()
    }

    /// The linear least-squares plane through stage readings (at least 3,
    /// not on one line); `None` where they do not span a plane.
    pub fn fit(points: &[Vector3<f64>], center_stage_mm: [f64; 2]) -> Option<WorldFrame> {
        let [cx, cy] = center_stage_mm;
        let rows = points.len();
        let a = nalgebra::DMatrix::from_fn(rows, 3, |r, c| match c {
            0 => 1.0,
            1 => points[r].x - cx,
            _ => points[r].y - cy,
        });
        let b = nalgebra::DVector::from_fn(rows, |r, _| points[r].z);
        let sol = (a.transpose() * &a).cholesky()?.solve(&(a.transpose() * b));
        Some(WorldFrame {
            plane: [sol[0], sol[1], sol[2]],
            center_stage_mm,
        })
    }
}

/// A point of the adjustment: the world frame's plane and the station in
/// that frame.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// The world frame.
    pub frame: WorldFrame,
    /// The station, world frame.
    pub station: Station,
}

impl State {
    /// This state with one parameter changed by `delta`.
    pub fn perturbed(&self, p: Param, delta: f64) -> State {
        let mut s = self.clone();
        match p {
            Param::PlaneHeight => s.frame.plane[0] += delta,
            Param::PlaneSlopeX => s.frame.plane[1] += delta,
            Param::PlaneSlopeY => s.frame.plane[2] += delta,
            Param::Station(d) => s.station = s.station.perturbed(d, delta),
            Param::CoverGlassThickness => {
                if let Some(g) = &mut s.station.screen.cover_glass {
                    g.thickness_mm += delta;
                }
            }
            Param::AspectRatio => {
                s.station.camera.aspect_ratio = Some(s.station.camera.aspect() + delta);
            }
        }
        s
    }
}

/// The change `d` (in the DOFs' coordinates, to first order) that takes
/// `from` to `to`: `to ≈ from` with every DOF of `names` changed by `d`.
/// Rotations are read off `R_to R_fromᵀ` as small world-axis angles; the
/// screen's position is its origin after the rotation about its centre.
pub fn difference(from: &State, to: &State, params: &[Param]) -> Vec<f64> {
    // The rotation vector from the antisymmetric part (`sin θ` times the
    // axis), exact to rounding at small angles, where reading θ off the
    // trace (`acos`) loses half the digits.
    let small_angles = |r: Rotation3<f64>| {
        let m = r.matrix();
        let v = 0.5
            * Vector3::new(
                m[(2, 1)] - m[(1, 2)],
                m[(0, 2)] - m[(2, 0)],
                m[(1, 0)] - m[(0, 1)],
            );
        let s = v.norm();
        if s == 0.0 {
            v
        } else {
            v * (s.min(1.0).asin().to_degrees() / s)
        }
    };
    let cam_w = small_angles(
        to.station.camera.world_from_camera * from.station.camera.world_from_camera.inverse(),
    );
    let (sf, st) = (&from.station.screen, &to.station.screen);
    let basis = |s: &crate::optics::station::Screen| {
        nalgebra::Matrix3::from_columns(&[
            s.u_axis.into_inner(),
            s.v_axis.into_inner(),
            s.normal().into_inner(),
        ])
    };
    let scr_r = Rotation3::from_matrix(&(basis(st) * basis(sf).transpose()));
    let scr_w = small_angles(scr_r);
    // Rotations and the pitch keep the centre: the position DOFs are its shift.
    let shift = st.centre() - sf.centre();
    let zero = Distortion {
        k: [0.0; 3],
        p: [0.0; 2],
    };
    let a = from.station.camera.distortion.unwrap_or(zero);
    let b = to.station.camera.distortion.unwrap_or(zero);
    let dk = [0, 1, 2].map(|i| b.k[i] - a.k[i]);
    let dp = [0, 1].map(|i| b.p[i] - a.p[i]);
    let (ef, et) = (&from.station.element.pose, &to.station.element.pose);
    params
        .iter()
        .map(|p| match p {
            Param::PlaneHeight => to.frame.plane[0] - from.frame.plane[0],
            Param::PlaneSlopeX => to.frame.plane[1] - from.frame.plane[1],
            Param::PlaneSlopeY => to.frame.plane[2] - from.frame.plane[2],
            Param::CoverGlassThickness => {
                let t = |s: &State| s.station.screen.cover_glass.map_or(0.0, |g| g.thickness_mm);
                t(to) - t(from)
            }
            Param::AspectRatio => to.station.camera.aspect() - from.station.camera.aspect(),
            Param::Station(d) => match d {
                Dof::CameraX => to.station.camera.position_mm.x - from.station.camera.position_mm.x,
                Dof::CameraY => to.station.camera.position_mm.y - from.station.camera.position_mm.y,
                Dof::CameraZ => to.station.camera.position_mm.z - from.station.camera.position_mm.z,
                Dof::CameraRx => cam_w.x,
                Dof::CameraRy => cam_w.y,
                Dof::CameraRz => cam_w.z,
                Dof::FocalLength => {
                    to.station.camera.focal_length_mm - from.station.camera.focal_length_mm
                }
                Dof::Cx => {
                    to.station.camera.principal_point_px.x
                        - from.station.camera.principal_point_px.x
                }
                Dof::Cy => {
                    to.station.camera.principal_point_px.y
                        - from.station.camera.principal_point_px.y
                }
                Dof::K1 => dk[0],
                Dof::K2 => dk[1],
                Dof::K3 => dk[2],
                Dof::P1 => dp[0],
                Dof::P2 => dp[1],
                Dof::ScreenX => shift.x,
                Dof::ScreenY => shift.y,
                Dof::ScreenZ => shift.z,
                Dof::ScreenRx => scr_w.x,
                Dof::ScreenRy => scr_w.y,
                Dof::ScreenRz => scr_w.z,
                Dof::ScreenPitch => st.pixel_pitch_mm - sf.pixel_pitch_mm,
                Dof::ElementX => et.offset_mm.x - ef.offset_mm.x,
                Dof::ElementY => et.offset_mm.y - ef.offset_mm.y,
                Dof::ElementZ => et.offset_mm.z - ef.offset_mm.z,
                Dof::ElementRx => et.tilt_deg[0] - ef.tilt_deg[0],
                Dof::ElementRy => et.tilt_deg[1] - ef.tilt_deg[1],
                Dof::Thickness => {
                    to.station.element.thickness_mm - from.station.element.thickness_mm
                }
                Dof::RefractiveIndex => {
                    to.station.element.refractive_index - from.station.element.refractive_index
                }
            },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> State {
        let station = crate::calibrate::simulate::example_truth().unwrap();
        State {
            frame: WorldFrame {
                plane: [12.3, 0.004, -0.003],
                center_stage_mm: [102.4, 87.9],
            },
            station,
        }
    }

    #[test]
    fn the_world_frame_follows_the_spec() {
        let f = state().frame;
        let r = f.stage_from_world();
        let (x, z) = (r * Vector3::x(), r * Vector3::z());
        // z: the plane's normal on the stage's +z side; x: the stage's x in the plane.
        assert!((z - Vector3::new(-0.004, 0.003, 1.0).normalize()).norm() < 1e-15);
        assert!(
            x.dot(&z).abs() < 1e-15 && x.dot(&z.cross(&Vector3::x())).abs() < 1e-15 && x.x > 0.0
        );
        // The origin is the plane's point at the element's centre.
        let o = f.to_world(&Vector3::new(102.4, 87.9, 12.3));
        assert!(o.coords.norm() < 1e-12);
        let p = Point3::new(10.0, -20.0, 300.0);
        assert!((f.to_world(&f.to_stage(&p)) - p).norm() < 1e-12);
        // A point of the plane is at world z = 0.
        let s = Vector3::new(150.0, 40.0, 12.3 + 0.004 * 47.6 + 0.003 * 47.9);
        assert!(f.to_world(&s).z.abs() < 1e-12);
    }

    #[test]
    fn difference_reads_back_every_change() {
        let from = state();
        let params: Vec<Param> = [
            Param::PlaneHeight,
            Param::PlaneSlopeX,
            Param::PlaneSlopeY,
            Param::CoverGlassThickness,
            Param::AspectRatio,
        ]
        .into_iter()
        .chain(STATION_DOFS.iter().map(|d| Param::Station(d.dof)))
        .collect();
        for (k, p) in params.iter().enumerate() {
            // A change of ten difference steps: small, far above rounding.
            let delta = 10.0 * p.step();
            let d = difference(&from, &from.perturbed(*p, delta), &params);
            for (m, v) in d.iter().enumerate() {
                let want = if m == k { delta } else { 0.0 };
                assert!(
                    (v - want).abs() < 1e-9 * delta.abs().max(1e-3),
                    "{} → {}: {v}",
                    p.name(),
                    params[m].name()
                );
            }
        }
    }

    #[test]
    fn names_read_back() {
        assert!(Param::from_name("camera.k3") == Some(Param::Station(Dof::K3)));
        assert!(Param::from_name("frame.slope_y") == Some(Param::PlaneSlopeY));
        // Given, not estimated.
        assert!(Param::from_name("element.thickness_mm").is_none());
        assert!(Param::from_name("camera.k4").is_none());
    }
}
