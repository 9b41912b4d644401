//! The screen's cover glass (station v2): a parallel slab on the viewer's
//! side of the pixel plane, touching it. A ray towards the screen refracts
//! into the slab at its outer face and lands on the pixel plane, shifted
//! sideways by `t (tan θ − tan θ_g)` from where it would have landed
//! without the glass.

use nalgebra::{Point3, Unit, Vector3};

use crate::optics::refraction::{refract, Dir, Refraction};

/// Thickness and index of the slab.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoverGlass {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Refractive index (> 1).
    pub refractive_index: f64,
}

/// Bisection steps of [`CoverGlass::entry_offset`]: 2⁻⁶⁰ of the lateral
/// distance, below a femtometre on any screen.
const BISECTIONS: usize = 60;

impl CoverGlass {
    /// Where a ray from `from` along `d` lands on the pixel plane through
    /// `origin` with unit normal `n_view` (pointing to the viewer's side,
    /// where `from` is). `None` when the ray does not go towards the screen.
    pub fn land(
        &self,
        origin: &Point3<f64>,
        n_view: &Unit<Vector3<f64>>,
        from: &Point3<f64>,
        d: &Dir,
    ) -> Option<Point3<f64>> {
        let approach = d.dot(n_view);
        let height = (from - origin).dot(n_view);
        if approach >= 0.0 || height <= self.thickness_mm {
            return None;
        }
        let s1 = (self.thickness_mm - height) / approach;
        let entry = from + s1 * d.as_ref();
        let Refraction::Transmitted {
            direction: inside, ..
        } = refract(d, n_view, 1.0, self.refractive_index)
        else {
            return None;
        };
        let s2 = -self.thickness_mm / inside.dot(n_view);
        Some(entry + s2 * inside.as_ref())
    }

    /// The lateral offset `a` of the entry point, along the plane, for a
    /// ray from a point at `height` above the pixel plane to a landing
    /// point `lateral` away along it: `a / √(a² + (h − t)²) = n_g (ℓ − a) /
    /// √((ℓ − a)² + t²)` (Snell), solved by bisection (the left side rises
    /// with `a`, the right side falls).
    pub fn entry_offset(&self, height: f64, lateral: f64) -> f64 {
        let (t, n) = (self.thickness_mm, self.refractive_index);
        let air = height - t;
        let snell = |a: f64| {
            let g = lateral - a;
            a / a.hypot(air) - n * g / g.hypot(t)
        };
        let (mut lo, mut hi) = (0.0, lateral);
        for _ in 0..BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if snell(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// The direction in air from `from` that lands on `target` on the pixel
    /// plane (through `origin`, unit normal `n_view` towards `from`).
    /// `None` when `from` is not beyond the glass.
    pub fn aim(
        &self,
        origin: &Point3<f64>,
        n_view: &Unit<Vector3<f64>>,
        from: &Point3<f64>,
        target: &Point3<f64>,
    ) -> Option<Dir> {
        let height = (from - origin).dot(n_view);
        if height <= self.thickness_mm {
            return None;
        }
        let foot = from - height * n_view.as_ref();
        let along = target - foot;
        let along = along - along.dot(n_view) * n_view.as_ref();
        let lateral = along.norm();
        if lateral == 0.0 {
            return Some(-*n_view);
        }
        let e = along / lateral;
        let a = self.entry_offset(height, lateral);
        Some(Unit::new_normalize(
            a * e - (height - self.thickness_mm) * n_view.as_ref(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glass() -> CoverGlass {
        CoverGlass {
            thickness_mm: 1.8,
            refractive_index: 1.52,
        }
    }

    #[test]
    fn lateral_shift_is_the_closed_form_of_a_slab() {
        let g = glass();
        let origin = Point3::origin();
        let n = Vector3::z_axis();
        let from = Point3::new(0.0, 0.0, 800.0);
        for deg in [0.0_f64, 5.0, 20.0, 40.0, 60.0] {
            let th = deg.to_radians();
            let d = Unit::new_normalize(Vector3::new(th.sin(), 0.0, -th.cos()));
            let hit = g.land(&origin, &n, &from, &d).expect("lands");
            let straight = 800.0 * th.tan();
            let thg = (th.sin() / 1.52).asin();
            let shift = 1.8 * (th.tan() - thg.tan());
            // Two plane intersections and one refraction in f64: ~1e-13 mm.
            assert!(
                (straight - hit.x - shift).abs() < 1e-10,
                "{deg}°: shift {} vs closed form {shift}",
                straight - hit.x
            );
            assert!(hit.z.abs() < 1e-12 && hit.y.abs() < 1e-12);
        }
    }

    #[test]
    fn aim_inverts_land() {
        let g = glass();
        let origin = Point3::new(5.0, -3.0, 825.0);
        let n = Unit::new_normalize(Vector3::new(0.05, 0.02, -1.0));
        let from = Point3::new(1.0, 2.0, 0.1);
        for target in [
            Point3::new(100.0, 40.0, 825.0 + 100.0 * 0.05 + 40.0 * 0.02),
            Point3::new(5.0, -3.0, 825.0),
        ] {
            // Put the target on the plane exactly.
            let target = target - (target - origin).dot(&n) * n.as_ref();
            let d = g.aim(&origin, &n, &from, &target).expect("aims");
            let hit = g.land(&origin, &n, &from, &d).expect("lands");
            // Bisection to 2⁻⁶⁰ of the lateral distance, then one trace.
            assert!((hit - target).norm() < 1e-9, "{}", (hit - target).norm());
        }
    }
}
