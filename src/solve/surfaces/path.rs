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

type D = Dual<LOCAL>;

/// A traced path: the screen point with its local derivatives and where the
/// path touched each surface.
#[derive(Debug, Clone, Copy)]
pub struct DualPath {
    /// Screen `u`, `v` (screen px) with derivatives over the [`LOCAL`] slots.
    pub uv: [D; 2],
    /// `(x, y)` world points, mm, of the slots' hits: front entry, back,
    /// front exit (the last two NaN for the front path).
    pub hits: [[f64; 2]; 3],
}

struct Hit {
    point: V3<LOCAL>,
    normal: V3<LOCAL>,
    xy: [f64; 2],
}

fn hit(plate: &Plate, o: &V3<LOCAL>, d: &V3<LOCAL>, back: bool, slot: usize) -> Result<Hit, Miss> {
    let (surface, z0): (&ZernikeSurface, f64) = if back {
        (&plate.back, -plate.thickness_mm)
    } else {
        (&plate.front, 0.0)
    };
    let ov = v3val(o);
    let dv = v3val(d);
    let origin = Point3::from(ov);
    let dir = Unit::new_unchecked(Vector3::from(dv));
    let h = intersect(&origin, &dir, surface, z0)?;
    let p0 = h.point;
    let (ex, ey) = (p0.x - plate.edge_center_mm.x, p0.y - plate.edge_center_mm.y);
    if ex * ex + ey * ey > plate.edge_radius_mm * plate.edge_radius_mm {
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
    let p = axpy(o, D::c(s0), d);
    let eps_h = D::param(0.0, slot);
    let g = p[2]
        - D::c(z0 + w0)
        - (p[0] - D::c(p0.x)).scale(wx)
        - (p[1] - D::c(p0.y)).scale(wy)
        - eps_h;
    let gprime = dv[2] - wx * dv[0] - wy * dv[1];
    let s = D::c(s0) - g.scale(1.0 / gprime);
    let point = axpy(o, s, d);
    // The slope where the perturbed path meets the surface: the gradient at
    // the converged point plus the Hessian times the point's shift (the
    // Hessian by a forward difference of the gradient over 1 µm: its error,
    // ~1 µm × the third derivative, is ~1e-3 of the curvature term, which is
    // itself ~1e-3 of the slope term on a window 60 nm out of flat).
    let hess = hessian(surface, p0.x, p0.y, wx, wy);
    let (dx, dy) = (point[0] - D::c(p0.x), point[1] - D::c(p0.y));
    let gx = D::param(wx, slot + 1) + dx.scale(hess[0]) + dy.scale(hess[1]);
    let gy = D::param(wy, slot + 2) + dx.scale(hess[1]) + dy.scale(hess[2]);
    let normal = normalize(&[-gx, -gy, D::c(1.0)]);
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

fn reflect(d: &V3<LOCAL>, n: &V3<LOCAL>) -> V3<LOCAL> {
    let k = dot(d, n).scale(-2.0);
    axpy(d, k, n)
}

fn refract(d: &V3<LOCAL>, n: &V3<LOCAL>, eta: f64) -> Result<V3<LOCAL>, Miss> {
    let c = -dot(d, n);
    let (m, cos_i) = if c.v >= 0.0 {
        (*n, c)
    } else {
        (scale(D::c(-1.0), n), -c)
    };
    let sin2_t = (D::c(1.0) - cos_i * cos_i).scale(eta * eta);
    if sin2_t.v > 1.0 {
        return Err(Miss::TotalInternalReflection);
    }
    let cos_t = (D::c(1.0) - sin2_t).sqrt();
    let t = axpy(&scale(D::c(eta), d), cos_i.scale(eta) - cos_t, &m);
    Ok(normalize(&t))
}

fn to_screen(screen: &Screen, p: &V3<LOCAL>, d: &V3<LOCAL>) -> Result<[D; 2], Miss> {
    let n = v3c(screen.normal().into_inner().into());
    let o: V3<LOCAL> = v3c(screen.origin_mm.coords.into());
    let (p, d) = match &screen.cover_glass {
        None => (*p, *d),
        Some(glass) => {
            // Into the glass at its outer face, a plane `thickness` above the
            // pixels on the viewer's side; the landing below is on the pixels.
            let nv = screen.normal_towards(&Point3::from(v3val(p)));
            let nv: V3<LOCAL> = v3c(nv.into_inner().into());
            let face = axpy(&o, D::c(glass.thickness_mm), &nv);
            let entry = to_plane(&face, &nv, p, d)?;
            let inside = refract(d, &nv, 1.0 / glass.refractive_index)?;
            (entry, inside)
        }
    };
    let x = to_plane(&o, &n, &p, &d)?;
    let rel = [x[0] - o[0], x[1] - o[1], x[2] - o[2]];
    let k = 1.0 / screen.pixel_pitch_mm;
    let u = dot(&rel, &v3c(screen.u_axis.into_inner().into())).scale(k);
    let v = dot(&rel, &v3c(screen.v_axis.into_inner().into())).scale(k);
    if !screen.contains(u.v, v.v) {
        return Err(Miss::OffScreen);
    }
    Ok([u, v])
}

/// Where the ray from `p` along `d` meets the plane through `o` with normal `n`.
fn to_plane(o: &V3<LOCAL>, n: &V3<LOCAL>, p: &V3<LOCAL>, d: &V3<LOCAL>) -> Result<V3<LOCAL>, Miss> {
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
    let o = v3c(camera.coords.into());
    let dd = v3c((*d).into());
    let m1 = hit(plate, &o, &dd, false, SLOT_FRONT_IN)?;
    let r = reflect(&dd, &m1.normal);
    let uv = to_screen(screen, &m1.point, &r)?;
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
    let n = plate.refractive_index;
    let o = v3c(camera.coords.into());
    let dd = v3c((*d).into());
    let m1 = hit(plate, &o, &dd, false, SLOT_FRONT_IN)?;
    let t1 = refract(&dd, &m1.normal, 1.0 / n)?;
    let mb = hit(plate, &m1.point, &t1, true, SLOT_BACK)?;
    let up = reflect(&t1, &mb.normal);
    let mf = hit(plate, &mb.point, &up, false, SLOT_FRONT_OUT)?;
    let out = refract(&up, &mf.normal, n)?;
    let uv = to_screen(screen, &mf.point, &out)?;
    Ok(DualPath {
        uv,
        hits: [m1.xy, mb.xy, mf.xy],
    })
}
