//! The station's degrees of freedom in dual numbers: every camera ray and
//! every traced screen point with its exact derivatives over all 28
//! degrees of freedom of `mfd-station-uncertainty/1` (`Dof::ALL`, the
//! spec's table as `Station::perturbed` applies it), beside the local
//! surface slots the solvers use.
//!
//! The station is built in [`Dual`]s of width [`WIDTH`]: slots
//! `0..LOCAL` are the surface slots of [`crate::solve::surfaces::path`],
//! slot `LOCAL + dof as usize` the degree of freedom `dof`. The traced
//! path is the solvers' own ([`front_path_in`], [`back_path_in`]); here
//! only the station's geometry gets its derivatives: the camera's centre
//! and rotation, its intrinsics and the Brown–Conrady inverse (a Newton
//! solve, differentiated by the implicit-function theorem: one dual Newton
//! step from the converged point), the element's pose (the frame every
//! stage traces in), the screen's placement and pitch, the plate's
//! thickness and index. Rotations of the table are about world axes by
//! degrees: their derivative at zero is `(π/180) e_k × w` for every
//! vector `w` they turn.
//!
//! Hand-written rather than a crate's: the solvers already trace in these
//! duals, and the derivative of the distortion's inverse needs its
//! converged point, which only this code has.

use nalgebra::Point3;

use crate::optics::station::{Distortion, Dof, Station};
use crate::optics::trace::{Miss, Plate};
use crate::solve::surfaces::dual::{
    cross, mat_mul, mat_vec, normalize, transpose, v3c, v3val, Dual, M3, V3,
};
use crate::solve::surfaces::path::{back_path_in, front_path_in, DualPath, DualScreen, Rig, LOCAL};

/// Number of degrees of freedom (`Dof::ALL`).
pub const DOFS: usize = Dof::ALL.len();
/// Width of the duals: the surface slots, then one per degree of freedom.
pub const WIDTH: usize = LOCAL + DOFS;

type D = Dual<WIDTH>;

/// `v` as the value of degree of freedom `dof`.
fn param(v: f64, dof: Dof) -> D {
    D::param(v, LOCAL + dof as usize)
}

/// `w` turned by the three world-axis rotations from `first` (x, y, z),
/// in degrees, to first order: `w + Σ_k δ_k (π/180) e_k × w`.
fn turned(w: [f64; 3], first: Dof) -> V3<WIDTH> {
    let mut out = v3c(w);
    let k = std::f64::consts::PI / 180.0;
    // e_x × w, e_y × w, e_z × w.
    let crosses = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]];
    for (axis, c) in crosses.iter().enumerate() {
        let slot = LOCAL + first as usize + axis;
        for (o, ci) in out.iter_mut().zip(c) {
            o.g[slot] += ci * k;
        }
    }
    out
}

/// `a + b`, `a − b` of vectors.
fn add(a: &V3<WIDTH>, b: &V3<WIDTH>) -> V3<WIDTH> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn sub(a: &V3<WIDTH>, b: &V3<WIDTH>) -> V3<WIDTH> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// A rotation about x (`axis` 0) or y (1) by the dual angle `a`, radians.
fn axis_rotation(axis: usize, a: D) -> M3<WIDTH> {
    let (c, s, o, l) = (a.cos(), a.sin(), D::c(0.0), D::c(1.0));
    if axis == 0 {
        [[l, o, o], [o, c, -s], [o, s, c]]
    } else {
        [[c, o, s], [o, l, o], [-s, o, c]]
    }
}

/// The station in dual numbers, in the element's own frame (the frame the
/// surfaces are traced, fitted and reported in).
#[derive(Debug, Clone)]
pub struct StationDual {
    /// Camera centre, plate and screen, element frame.
    pub rig: Rig<WIDTH>,
    /// Rotation taking camera-frame vectors to the element frame.
    element_from_camera: M3<WIDTH>,
    /// Focal lengths in camera pixels along the columns and the rows
    /// (`fy = aspect · fx`; the aspect ratio is not a degree of freedom of
    /// `mfd-station-uncertainty/1`), and the principal point, px.
    focal_px: [D; 2],
    principal_px: [D; 2],
    /// Distortion coefficients `k1..k3, p1, p2` (zero where the station has none).
    k: [D; 3],
    p: [D; 2],
    /// The station's own distortion, for the converged inverse.
    distortion: Option<Distortion>,
}

impl StationDual {
    /// `station` (world frame, its element's pose included) with every
    /// degree of freedom a dual slot.
    pub fn new(station: &Station) -> Self {
        use Dof::*;
        let cam = &station.camera;
        let scr = &station.screen;
        let e = &station.element;
        let deg = std::f64::consts::PI / 180.0;
        // The element's pose: p' = c + Rᵀ (p − offset − c), R = R_y(ry) R_x(rx).
        let rx = param(e.pose.tilt_deg[0], ElementRx).scale(deg);
        let ry = param(e.pose.tilt_deg[1], ElementRy).scale(deg);
        let back = transpose(&mat_mul(&axis_rotation(1, ry), &axis_rotation(0, rx)));
        let off: V3<WIDTH> =
            std::array::from_fn(|a| param(e.pose.offset_mm[a], [ElementX, ElementY, ElementZ][a]));
        let c = v3c(e.pivot().coords.into());
        let to_element = |p: &V3<WIDTH>| add(&c, &mat_vec(&back, &sub(&sub(p, &off), &c)));
        // The camera: centre, and rotation turned about the world axes.
        let centre: V3<WIDTH> =
            std::array::from_fn(|a| param(cam.position_mm[a], [CameraX, CameraY, CameraZ][a]));
        let r = cam.world_from_camera.matrix();
        let cols: [V3<WIDTH>; 3] =
            std::array::from_fn(|k| turned([r[(0, k)], r[(1, k)], r[(2, k)]], CameraRx));
        let world_from_camera: M3<WIDTH> =
            std::array::from_fn(|a| std::array::from_fn(|k| cols[k][a]));
        // The screen: origin along the world axes, turned about its centre
        // Q, and moved by the pitch with Q fixed.
        let u0: [f64; 3] = scr.u_axis.into_inner().into();
        let v0: [f64; 3] = scr.v_axis.into_inner().into();
        let q = scr.centre();
        let from_q: [f64; 3] = (scr.origin_mm - q).into();
        let mut origin = turned(from_q, ScreenRx);
        for (a, o) in origin.iter_mut().enumerate() {
            *o = *o + param(q[a], [ScreenX, ScreenY, ScreenZ][a]);
            let half = 0.5 * (f64::from(scr.width) * u0[a] + f64::from(scr.height) * v0[a]);
            o.g[LOCAL + ScreenPitch as usize] -= half;
        }
        let pitch = param(scr.pixel_pitch_mm, ScreenPitch);
        let u_axis = mat_vec(&back, &turned(u0, ScreenRx));
        let v_axis = mat_vec(&back, &turned(v0, ScreenRx));
        let screen = DualScreen {
            origin: to_element(&origin),
            u_axis,
            v_axis,
            normal: normalize(&cross(&u_axis, &v_axis)),
            px_per_mm: D::c(1.0) / pitch,
            cover_glass: scr.cover_glass,
            size: [scr.width, scr.height],
        };
        let dist = cam.distortion.unwrap_or(Distortion {
            k: [0.0; 3],
            p: [0.0; 2],
        });
        StationDual {
            rig: Rig {
                camera: to_element(&centre),
                thickness_mm: param(e.thickness_mm, Thickness),
                refractive_index: param(e.refractive_index, RefractiveIndex),
                screen,
                central_hessian: true,
            },
            element_from_camera: mat_mul(&back, &world_from_camera),
            focal_px: {
                let fx = param(cam.focal_length_mm, FocalLength).scale(1.0 / cam.pixel_pitch_mm);
                [fx, fx.scale(cam.aspect())]
            },
            principal_px: [
                param(cam.principal_point_px.x, Cx),
                param(cam.principal_point_px.y, Cy),
            ],
            k: std::array::from_fn(|a| param(dist.k[a], [K1, K2, K3][a])),
            p: std::array::from_fn(|a| param(dist.p[a], [P1, P2][a])),
            distortion: cam.distortion,
        }
    }

    /// The unit direction, element frame, of the camera ray through the
    /// centre of pixel `(i, j)` (as `Camera::ray_direction`), `None` where
    /// the distortion's inverse does not converge.
    pub fn ray(&self, i: u32, j: u32) -> Option<V3<WIDTH>> {
        let xy_px = [f64::from(i) + 0.5, f64::from(j) + 0.5];
        let xd: [D; 2] =
            std::array::from_fn(|a| (D::c(xy_px[a]) - self.principal_px[a]) / self.focal_px[a]);
        let (x0, y0) = match &self.distortion {
            None => (xd[0].v, xd[1].v),
            Some(d) => d.undistort(xd[0].v, xd[1].v)?,
        };
        // One Newton step in duals from the converged ideal point: the
        // implicit function x(k, p, xd) of distort(x; k, p) = xd.
        let [k1, k2, k3] = self.k;
        let [p1, p2] = self.p;
        let r2 = x0 * x0 + y0 * y0;
        let f = D::c(1.0) + (k1 + (k2 + k3.scale(r2)).scale(r2)).scale(r2);
        let ex = f.scale(x0) + p1.scale(2.0 * x0 * y0) + p2.scale(r2 + 2.0 * x0 * x0) - xd[0];
        let ey = f.scale(y0) + p1.scale(r2 + 2.0 * y0 * y0) + p2.scale(2.0 * x0 * y0) - xd[1];
        let value = Distortion {
            k: self.k.map(|c| c.v),
            p: self.p.map(|c| c.v),
        };
        let j = value.jacobian(x0, y0);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        let x = D::c(x0) - (ex.scale(j[1][1]) - ey.scale(j[0][1])).scale(1.0 / det);
        let y = D::c(y0) - (ey.scale(j[0][0]) - ex.scale(j[1][0])).scale(1.0 / det);
        Some(normalize(&mat_vec(
            &self.element_from_camera,
            &[x, y, D::c(1.0)],
        )))
    }

    /// The camera centre's value, element frame, mm.
    pub fn camera_mm(&self) -> Point3<f64> {
        Point3::from(v3val(&self.rig.camera))
    }

    /// The path of reflection `k` (0 front, 1 back) of pixel `(i, j)`
    /// through `plate`, with derivatives over the surface slots and every
    /// degree of freedom.
    ///
    /// # Errors
    /// The [`Miss`] that ends the path; [`Miss::NoConvergence`] where the
    /// distortion's inverse does not converge.
    pub fn path(&self, plate: &Plate, pixel: [u32; 2], k: usize) -> Result<DualPath<WIDTH>, Miss> {
        let d = self.ray(pixel[0], pixel[1]).ok_or(Miss::NoConvergence)?;
        if k == 0 {
            front_path_in(plate, &self.rig, &d)
        } else {
            back_path_in(plate, &self.rig, &d)
        }
    }
}
