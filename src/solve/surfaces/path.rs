//! The inverse ray tracer's light paths, evaluated in dual numbers.
//!
//! Each surface interaction carries three local perturbation parameters:
//! a height offset `h` (mm) and slope offsets `gx`, `gy` (mm/mm) of the
//! surface at the hit point. A Zernike coefficient changes a surface by
//! `Z_j` in height and `∇Z_j` in slope, so the Jacobian of a screen point
//! with respect to every coefficient is the local 2 × 3 block of the slot
//! times the basis values at the hit point: one trace per pixel, no finite
//! differences. The slots of [`LOCAL`]: 0–2 the front where the camera ray
//! meets it, 3–5 the back, 6–8 the front where the back reflection leaves.
//! The slope seen by a perturbed path includes the surface's curvature
//! times the shift of the hit point, so the derivatives are those of the
//! exact path (to the Hessian's difference error): Gauss–Newton converges
//! in two or three steps.

use nalgebra::{Point3, Unit, Vector3};

use super::dual::{axpy, dot, normalize, scale, v3c, v3val, Dual, V3};
use crate::optics::station::Screen;
use crate::optics::trace::{intersect, Miss, Plate};
use crate::optics::zernike::ZernikeSurface;

/// Number of local parameters of a path (three per surface interaction).
pub const LOCAL: usize = 9;
/// Slot of the front surface where the camera ray meets it.
pub const SLOT_FRONT_IN: usize = 0;
/// Slot of the back surface.
pub const SLOT_BACK: usize = 3;
/// Slot of the front surface where the back reflection leaves the element.
pub const SLOT_FRONT_OUT: usize = 6;

/// The geometry a path is traced through, in dual numbers: the camera's
/// projection centre, the plate's thickness and index, and the screen.
/// The surface solvers hold it constant ([`Rig::constant`], `N` =
/// [`LOCAL`]); the error budget gives it derivatives over the station's
/// degrees of freedom in the slots from [`LOCAL`] on.
#[derive(Debug, Clone, Copy)]
pub struct Rig<const N: usize> {
    /// Projection centre, element frame, mm.
    pub camera: V3<N>,
    /// Plate thickness, mm (the back's reference plane is `z = −thickness`).
    pub thickness_mm: Dual<N>,
    /// Plate refractive index.
    pub refractive_index: Dual<N>,
    /// The screen.
    pub screen: DualScreen<N>,
    /// The surfaces' Hessian (the curvature term of a perturbed path's
    /// slope) by central rather than forward differences of the gradient:
    /// error ~(1 µm)² W'''' instead of ~1 µm W''', for derivatives checked
    /// to ~1e-6 (the error budget's); the solvers keep the forward one.
    pub central_hessian: bool,
}

/// A screen in dual numbers: where its pixels are and how they are spaced.
#[derive(Debug, Clone, Copy)]
pub struct DualScreen<const N: usize> {
    /// World position of `(u, v) = (0, 0)`, mm.
    pub origin: V3<N>,
    /// Unit direction of increasing u.
    pub u_axis: V3<N>,
    /// Unit direction of increasing v.
    pub v_axis: V3<N>,
    /// Unit normal `u × v`.
    pub normal: V3<N>,
    /// `1 / pixel pitch`, screen px per mm.
    pub px_per_mm: Dual<N>,
    /// The cover glass (no degree of freedom of its own).
    pub cover_glass: Option<crate::optics::station::CoverGlass>,
    /// Width and height, screen px.
    pub size: [u32; 2],
}

impl<const N: usize> DualScreen<N> {
    /// `screen` with no derivatives.
    pub fn constant(screen: &Screen) -> Self {
        DualScreen {
            origin: v3c(screen.origin_mm.coords.into()),
            u_axis: v3c(screen.u_axis.into_inner().into()),
            v_axis: v3c(screen.v_axis.into_inner().into()),
            normal: v3c(screen.normal().into_inner().into()),
            px_per_mm: Dual::c(1.0 / screen.pixel_pitch_mm),
            cover_glass: screen.cover_glass,
            size: [screen.width, screen.height],
        }
    }

    /// The unit normal on the side of `p` (the viewer's side).
    fn normal_towards(&self, p: [f64; 3]) -> V3<N> {
        let o = v3val(&self.origin);
        let n = v3val(&self.normal);
        let side = (p[0] - o[0]) * n[0] + (p[1] - o[1]) * n[1] + (p[2] - o[2]) * n[2];
        if side >= 0.0 {
            self.normal
        } else {
            self.normal.map(|x| -x)
        }
    }
}

impl<const N: usize> Rig<N> {
    /// The plate's and screen's geometry and the camera at `camera`, with
    /// no derivatives.
    pub fn constant(plate: &Plate, camera: &Point3<f64>, screen: &Screen) -> Self {
        Rig {
            camera: v3c(camera.coords.into()),
            thickness_mm: Dual::c(plate.thickness_mm),
            refractive_index: Dual::c(plate.refractive_index),
            screen: DualScreen::constant(screen),
            central_hessian: false,
        }
    }
}

/// A traced path: the screen point with its derivatives and where the
/// path touched each surface.
#[derive(Debug, Clone, Copy)]
pub struct DualPath<const N: usize = LOCAL> {
    /// Screen `u`, `v` (screen px) with derivatives over the [`LOCAL`]
    /// slots (and, for `N` > [`LOCAL`], the rig's parameters after them).
    pub uv: [Dual<N>; 2],
    /// `(x, y)` world points, mm, of the slots' hits: front entry, back,
    /// front exit (the last two NaN for the front path).
    pub hits: [[f64; 2]; 3],
}

struct Hit<const N: usize> {
    point: V3<N>,
    normal: V3<N>,
    xy: [f64; 2],
}

fn hit<const N: usize>(
    plate: &Plate,
    rig: &Rig<N>,
    o: &V3<N>,
    d: &V3<N>,
    back: bool,
    slot: usize,
) -> Result<Hit<N>, Miss> {
    let (surface, z0d): (&ZernikeSurface, Dual<N>) = if back {
        (&plate.back, -rig.thickness_mm)
    } else {
        (&plate.front, Dual::c(0.0))
    };
    let z0 = z0d.v;
    let ov = v3val(o);
    let dv = v3val(d);
    let origin = Point3::from(ov);
    let dir = Unit::new_unchecked(Vector3::from(dv));
    let h = intersect(&origin, &dir, surface, z0)?;
    let p0 = h.point;
    if plate.outside_edge_xy(p0.x, p0.y) {
        return Err(Miss::LeavesEdge {
            surface: u8::from(back),
        });
    }
    let (wx, wy) = (-h.normal.x / h.normal.z, -h.normal.y / h.normal.z);
    let w0 = p0.z - z0;
    // One Newton step in duals from the converged point: its value is the
    // point itself, its derivatives those of the implicit intersection.
    let s0 = ((p0.x - ov[0]) * dv[0] + (p0.y - ov[1]) * dv[1] + (p0.z - ov[2]) * dv[2])
        / (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]);
    let p = axpy(o, Dual::c(s0), d);
    let eps_h = Dual::param(0.0, slot);
    let g = p[2]
        - (z0d + Dual::c(w0))
        - (p[0] - Dual::c(p0.x)).scale(wx)
        - (p[1] - Dual::c(p0.y)).scale(wy)
        - eps_h;
    let gprime = dv[2] - wx * dv[0] - wy * dv[1];
    let s = Dual::c(s0) - g.scale(1.0 / gprime);
    let point = axpy(o, s, d);
    // The slope where the perturbed path meets the surface: the gradient at
    // the converged point plus the Hessian times the point's shift (the
    // Hessian by a forward difference of the gradient over 1 µm: its error,
    // ~1 µm × the third derivative, is ~1e-3 of the curvature term, which is
    // itself ~1e-3 of the slope term on a window 60 nm out of flat).
    let hess = if rig.central_hessian {
        hessian_central(surface, p0.x, p0.y)
    } else {
        hessian(surface, p0.x, p0.y, wx, wy)
    };
    let (dx, dy) = (point[0] - Dual::c(p0.x), point[1] - Dual::c(p0.y));
    let gx = Dual::param(wx, slot + 1) + dx.scale(hess[0]) + dy.scale(hess[1]);
    let gy = Dual::param(wy, slot + 2) + dx.scale(hess[1]) + dy.scale(hess[2]);
    let normal = normalize(&[-gx, -gy, Dual::c(1.0)]);
    Ok(Hit {
        point,
        normal,
        xy: [p0.x, p0.y],
    })
}

/// `[W_xx, W_xy, W_yy]` at `(x, y)` from the gradient there (`wx`, `wy`)
/// and one step along each axis; zero for a flat surface.
fn hessian(surface: &ZernikeSurface, x: f64, y: f64, wx: f64, wy: f64) -> [f64; 3] {
    if surface.is_flat() {
        return [0.0; 3];
    }
    const H: f64 = 1e-3;
    let (_, gxx, gyx) = surface.height_and_gradient(x + H, y);
    let (_, gxy, gyy) = surface.height_and_gradient(x, y + H);
    let wxy = 0.5 * ((gyx - wy) + (gxy - wx)) / H;
    [(gxx - wx) / H, wxy, (gyy - wy) / H]
}

/// [`hessian`] by central differences over ±1 µm.
fn hessian_central(surface: &ZernikeSurface, x: f64, y: f64) -> [f64; 3] {
    if surface.is_flat() {
        return [0.0; 3];
    }
    const H: f64 = 1e-3;
    let (_, gxp, gyxp) = surface.height_and_gradient(x + H, y);
    let (_, gxm, gyxm) = surface.height_and_gradient(x - H, y);
    let (_, gxyp, gyp) = surface.height_and_gradient(x, y + H);
    let (_, gxym, gym) = surface.height_and_gradient(x, y - H);
    let k = 0.5 / H;
    let wxy = 0.5 * ((gyxp - gyxm) + (gxyp - gxym)) * k;
    [(gxp - gxm) * k, wxy, (gyp - gym) * k]
}

fn reflect<const N: usize>(d: &V3<N>, n: &V3<N>) -> V3<N> {
    let k = dot(d, n).scale(-2.0);
    axpy(d, k, n)
}

fn refract<const N: usize>(d: &V3<N>, n: &V3<N>, eta: Dual<N>) -> Result<V3<N>, Miss> {
    let c = -dot(d, n);
    let (m, cos_i) = if c.v >= 0.0 {
        (*n, c)
    } else {
        (scale(Dual::c(-1.0), n), -c)
    };
    let sin2_t = (Dual::c(1.0) - cos_i * cos_i) * (eta * eta);
    if sin2_t.v > 1.0 {
        return Err(Miss::TotalInternalReflection);
    }
    let cos_t = (Dual::c(1.0) - sin2_t).sqrt();
    let t = axpy(&scale(eta, d), cos_i * eta - cos_t, &m);
    Ok(normalize(&t))
}

fn to_screen<const N: usize>(
    screen: &DualScreen<N>,
    p: &V3<N>,
    d: &V3<N>,
) -> Result<[Dual<N>; 2], Miss> {
    let n = screen.normal;
    let o = screen.origin;
    let (p, d) = match &screen.cover_glass {
        None => (*p, *d),
        Some(glass) => {
            // Into the glass at its outer face, a plane `thickness` above the
            // pixels on the viewer's side; the landing below is on the pixels.
            let nv = screen.normal_towards(v3val(p));
            let face = axpy(&o, Dual::c(glass.thickness_mm), &nv);
            let entry = to_plane(&face, &nv, p, d)?;
            let inside = refract(d, &nv, Dual::c(1.0 / glass.refractive_index))?;
            (entry, inside)
        }
    };
    let x = to_plane(&o, &n, &p, &d)?;
    let rel = [x[0] - o[0], x[1] - o[1], x[2] - o[2]];
    let k = screen.px_per_mm;
    let u = dot(&rel, &screen.u_axis) * k;
    let v = dot(&rel, &screen.v_axis) * k;
    let [w, h] = screen.size.map(f64::from);
    if !((0.0..=w).contains(&u.v) && (0.0..=h).contains(&v.v)) {
        return Err(Miss::OffScreen);
    }
    Ok([u, v])
}

/// Where the ray from `p` along `d` meets the plane through `o` with normal `n`.
fn to_plane<const N: usize>(o: &V3<N>, n: &V3<N>, p: &V3<N>, d: &V3<N>) -> Result<V3<N>, Miss> {
    let denom = dot(d, n);
    if denom.v.abs() < 1e-12 {
        return Err(Miss::ScreenMissed);
    }
    let op = [o[0] - p[0], o[1] - p[1], o[2] - p[2]];
    let s = dot(&op, n) / denom;
    if s.v <= 0.0 {
        return Err(Miss::ScreenMissed);
    }
    Ok(axpy(p, s, d))
}

/// The front reflection of the camera ray from `camera` along `d` (S1).
///
/// # Errors
/// The [`Miss`] that ends the path.
pub fn front_path(
    plate: &Plate,
    camera: &Point3<f64>,
    d: &Vector3<f64>,
    screen: &Screen,
) -> Result<DualPath, Miss> {
    let rig = Rig::<LOCAL>::constant(plate, camera, screen);
    front_path_in(plate, &rig, &v3c((*d).into()))
}

/// [`front_path`] through a rig in dual numbers, the camera ray `d` too.
///
/// # Errors
/// The [`Miss`] that ends the path.
pub fn front_path_in<const N: usize>(
    plate: &Plate,
    rig: &Rig<N>,
    d: &V3<N>,
) -> Result<DualPath<N>, Miss> {
    let m1 = hit(plate, rig, &rig.camera, d, false, SLOT_FRONT_IN)?;
    let r = reflect(d, &m1.normal);
    let uv = to_screen(&rig.screen, &m1.point, &r)?;
    Ok(DualPath {
        uv,
        hits: [m1.xy, [f64::NAN; 2], [f64::NAN; 2]],
    })
}

/// The back reflection (S2): refraction in at the front, reflection at the
/// back, refraction out through the front.
///
/// # Errors
/// The [`Miss`] that ends the path (rim, total internal reflection, screen).
pub fn back_path(
    plate: &Plate,
    camera: &Point3<f64>,
    d: &Vector3<f64>,
    screen: &Screen,
) -> Result<DualPath, Miss> {
    let rig = Rig::<LOCAL>::constant(plate, camera, screen);
    back_path_in(plate, &rig, &v3c((*d).into()))
}

/// [`back_path`] through a rig in dual numbers, the camera ray `d` too.
///
/// # Errors
/// The [`Miss`] that ends the path (rim, total internal reflection, screen).
pub fn back_path_in<const N: usize>(
    plate: &Plate,
    rig: &Rig<N>,
    d: &V3<N>,
) -> Result<DualPath<N>, Miss> {
    let n = rig.refractive_index;
    let m1 = hit(plate, rig, &rig.camera, d, false, SLOT_FRONT_IN)?;
    let t1 = refract(d, &m1.normal, Dual::c(1.0) / n)?;
    let mb = hit(plate, rig, &m1.point, &t1, true, SLOT_BACK)?;
    let up = reflect(&t1, &mb.normal);
    let mf = hit(plate, rig, &mb.point, &up, false, SLOT_FRONT_OUT)?;
    let out = refract(&up, &mf.normal, n)?;
    let uv = to_screen(&rig.screen, &mf.point, &out)?;
    Ok(DualPath {
        uv,
        hits: [m1.xy, mb.xy, mf.xy],
    })
}
