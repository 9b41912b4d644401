//! Ray–surface intersection by Newton's method on the surface's height.

use nalgebra::{Point3, Unit, Vector3};

use crate::optics::refraction::Dir;
use crate::optics::zernike::ZernikeSurface;

/// Newton stops when the height residual is below this, mm. The issue asks
/// for 1e-12 mm; coordinates near the element are ≲ 100 mm, where one f64
/// ulp is 1.4e-14 mm, so the bound is reachable with two decades to spare.
pub const INTERSECT_TOL_MM: f64 = 1e-12;
/// Iteration cap; surfaces within tens of µm of a plane converge in 2–4.
const MAX_NEWTON: usize = 50;

/// A point on a surface with the surface's unit normal there (pointing +z).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceHit {
    /// Intersection point, world frame, mm.
    pub point: Point3<f64>,
    /// Unit normal `(−∂W/∂x, −∂W/∂y, 1)/‖·‖`, world frame.
    pub normal: Dir,
}

/// Why an intersection failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntersectFailure {
    /// The ray runs parallel to the reference plane or away from it.
    NoCrossing,
    /// Newton did not reach [`INTERSECT_TOL_MM`] (grazing ray or a surface
    /// far from plane).
    NoConvergence,
}

/// Unit normal, pointing +z, of the surface `z = z0 + W` with gradient `(wx, wy)`.
pub fn surface_normal(wx: f64, wy: f64) -> Dir {
    Unit::new_normalize(Vector3::new(-wx, -wy, 1.0))
}

/// Intersects the ray `origin + s d` (s > 0) with the surface
/// `z = z0_mm + W(x, y)`: first with the plane `z = z0_mm`, then Newton on
/// `g(s) = z(s) − z0 − W(x(s), y(s))` from there, `g' = d_z − ∇W·d_xy`.
///
/// # Errors
/// [`IntersectFailure`] when the ray does not cross the plane going forward
/// or Newton does not converge.
pub fn intersect(
    origin: &Point3<f64>,
    d: &Dir,
    surface: &ZernikeSurface,
    z0_mm: f64,
) -> Result<SurfaceHit, IntersectFailure> {
    if d.z.abs() < 1e-12 {
        return Err(IntersectFailure::NoCrossing);
    }
    let s_plane = (z0_mm - origin.z) / d.z;
    if s_plane <= 0.0 {
        return Err(IntersectFailure::NoCrossing);
    }
    // Newton runs on the offset from the plane hit, so the step sizes are
    // micrometres and keep full relative precision.
    let base = origin + s_plane * d.as_ref();
    if surface.is_flat() {
        return Ok(SurfaceHit {
            point: base,
            normal: surface_normal(0.0, 0.0),
        });
    }
    let mut s = 0.0;
    for _ in 0..MAX_NEWTON {
        let p = base + s * d.as_ref();
        let (w, wx, wy) = surface.height_and_gradient(p.x, p.y);
        let g = (p.z - z0_mm) - w;
        let dg = d.z - wx * d.x - wy * d.y;
        if dg.abs() < 1e-9 {
            return Err(IntersectFailure::NoConvergence);
        }
        let step = g / dg;
        s -= step;
        if g.abs() < INTERSECT_TOL_MM && step.abs() < INTERSECT_TOL_MM {
            let p = base + s * d.as_ref();
            let (_, wx, wy) = surface.height_and_gradient(p.x, p.y);
            return Ok(SurfaceHit {
                point: p,
                normal: surface_normal(wx, wy),
            });
        }
    }
    Err(IntersectFailure::NoConvergence)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::zernike::{ZernikeBasis, ZernikeSurface};

    #[test]
    fn newton_lands_on_a_curved_surface() {
        let basis = ZernikeBasis::new(15, 25.0, [0.0, 0.0]).unwrap();
        // 5 µm of defocus and 2 µm of coma: far more than a real window.
        let mut c = vec![0.0; 15];
        c[3] = 5000.0;
        c[7] = 2000.0;
        let surf = ZernikeSurface::new(basis, c).unwrap();
        let o = Point3::new(-200.0, 30.0, 800.0);
        let d = Unit::new_normalize(Vector3::new(210.0, -42.0, -800.0));
        let hit = intersect(&o, &d, &surf, -3.0).unwrap();
        let w = surf.height_mm(hit.point.x, hit.point.y);
        assert!((hit.point.z - (-3.0 + w)).abs() <= INTERSECT_TOL_MM);
        // The hit lies on the ray: its offset from the origin is parallel to d.
        assert!((hit.point - o).normalize().cross(&d).norm() < 1e-14);
    }
}
