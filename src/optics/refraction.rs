//! Vector laws of reflection and refraction and unpolarised Fresnel
//! reflectance. Directions are unit vectors in the world frame; a surface
//! normal may point to either side (the functions orient it themselves).

use nalgebra::{Unit, Vector3};

/// A unit direction in the world frame.
pub type Dir = Unit<Vector3<f64>>;

/// Mirror reflection of direction `d` at a surface of normal `n`:
/// `r = d − 2 (d·n) n`.
pub fn reflect(d: &Dir, n: &Dir) -> Dir {
    let dn = d.dot(n);
    Unit::new_unchecked(d.as_ref() - 2.0 * dn * n.as_ref())
}

/// Outcome of refraction at an interface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refraction {
    /// The transmitted direction and the cosines of the incidence and
    /// refraction angles (both ≥ 0).
    Transmitted {
        /// Refracted unit direction.
        direction: Dir,
        /// cos of the angle of incidence.
        cos_incidence: f64,
        /// cos of the angle of refraction.
        cos_transmission: f64,
    },
    /// Total internal reflection: no transmitted ray exists.
    TotalInternalReflection {
        /// cos of the angle of incidence.
        cos_incidence: f64,
    },
}

/// Snell refraction of direction `d` going from index `n1` into index `n2`
/// through a surface of normal `n` (either orientation), in vector form:
/// `t = η d + (η cos i − cos t) m`, with `m` the normal facing the incoming
/// ray, `η = n1/n2`, `cos t = sqrt(1 − η² (1 − cos² i))`.
pub fn refract(d: &Dir, n: &Dir, n1: f64, n2: f64) -> Refraction {
    // Orient the normal against the incoming ray.
    let (m, cos_i) = {
        let c = -d.dot(n);
        if c >= 0.0 {
            (n.into_inner(), c)
        } else {
            (-n.into_inner(), -c)
        }
    };
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t > 1.0 {
        return Refraction::TotalInternalReflection {
            cos_incidence: cos_i,
        };
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = eta * d.as_ref() + (eta * cos_i - cos_t) * m;
    Refraction::Transmitted {
        direction: Unit::new_normalize(t),
        cos_incidence: cos_i,
        cos_transmission: cos_t,
    }
}

/// Fresnel power reflectances `(R_s, R_p)` for light going from index `n1`
/// into `n2` with incidence cosine `cos_i`; `(1, 1)` beyond the critical angle.
pub fn fresnel_sp(cos_i: f64, n1: f64, n2: f64) -> (f64, f64) {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (n1 / n2).powi(2) * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return (1.0, 1.0);
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t);
    (rs * rs, rp * rp)
}

/// Unpolarised Fresnel power reflectance, the mean of `R_s` and `R_p`.
pub fn reflectance(cos_i: f64, n1: f64, n2: f64) -> f64 {
    let (rs, rp) = fresnel_sp(cos_i, n1, n2);
    0.5 * (rs + rp)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn dir(x: f64, y: f64, z: f64) -> Dir {
        Unit::new_normalize(Vector3::new(x, y, z))
    }

    #[test]
    fn normal_incidence_reflectance_is_closed_form() {
        // ((n−1)/(n+1))² for n = 1.5 is exactly 0.04; rounding only.
        assert!((reflectance(1.0, 1.0, 1.5) - 0.04).abs() < 1e-15);
    }

    #[test]
    fn brewster_angle_kills_p() {
        // At tan θ_B = n2/n1 the p reflectance vanishes (closed form).
        let theta_b = 1.5f64.atan();
        let (rs, rp) = fresnel_sp(theta_b.cos(), 1.0, 1.5);
        assert!(rp < 1e-30, "rp = {rp}");
        assert!(rs > 0.1);
    }

    #[test]
    fn total_internal_reflection_is_reported_not_nan() {
        // Critical angle of glass n = 1.5: asin(1/1.5) = 41.8°; 60° is beyond.
        let d = dir(60f64.to_radians().sin(), 0.0, 60f64.to_radians().cos());
        let n = dir(0.0, 0.0, 1.0);
        assert!(matches!(
            refract(&d, &n, 1.5, 1.0),
            Refraction::TotalInternalReflection { .. }
        ));
        assert_eq!(fresnel_sp(60f64.to_radians().cos(), 1.5, 1.0), (1.0, 1.0));
    }

    proptest! {
        #[test]
        fn refraction_is_reversible(ax in -1.0f64..1.0, ay in -1.0f64..1.0,
                                   nx in -0.3f64..0.3, ny in -0.3f64..0.3,
                                   n2 in 1.01f64..2.6) {
            // Going in and coming back out along the reversed ray retraces the
            // path (optical reversibility); only rounding separates them.
            let d = dir(ax, ay, -1.0);
            let n = dir(nx, ny, 1.0);
            let Refraction::Transmitted { direction: t, .. } = refract(&d, &n, 1.0, n2) else {
                panic!("air to glass cannot be totally reflected");
            };
            let back = Unit::new_unchecked(-t.into_inner());
            let Refraction::Transmitted { direction: out, .. } = refract(&back, &n, n2, 1.0) else {
                panic!("the reversed ray is inside the critical angle by construction");
            };
            prop_assert!((out.into_inner() + d.into_inner()).norm() < 1e-12);
        }

        #[test]
        fn snell_law_and_coplanarity(ax in -1.0f64..1.0, ay in -1.0f64..1.0,
                                     n2 in 1.01f64..2.6) {
            let d = dir(ax, ay, -1.0);
            let n = dir(0.05, -0.02, 1.0);
            let Refraction::Transmitted { direction: t, cos_incidence, cos_transmission } =
                refract(&d, &n, 1.0, n2) else { panic!("no TIR from air") };
            let sin_i = (1.0 - cos_incidence.powi(2)).sqrt();
            let sin_t = (1.0 - cos_transmission.powi(2)).sqrt();
            prop_assert!((sin_i - n2 * sin_t).abs() < 1e-12);
            // d, n, t coplanar: the triple product vanishes.
            prop_assert!(d.cross(&n).dot(&t).abs() < 1e-12);
            prop_assert!((t.norm() - 1.0).abs() < 1e-14);
        }

        #[test]
        fn reflection_preserves_tangential_part(ax in -1.0f64..1.0, ay in -1.0f64..1.0) {
            let d = dir(ax, ay, -1.0);
            let n = dir(0.1, 0.2, 1.0);
            let r = reflect(&d, &n);
            prop_assert!((r.dot(&n) + d.dot(&n)).abs() < 1e-14);
            prop_assert!((r.cross(&n) - d.cross(&n)).norm() < 1e-14);
        }

        #[test]
        fn fresnel_reciprocity(cos_i in 0.05f64..1.0, n2 in 1.05f64..2.6) {
            // Stokes: the reflectance is the same seen from either side at the
            // conjugate angles, so R + T = 1 on both sides with one T.
            let sin_t = (1.0 - cos_i * cos_i).sqrt() / n2;
            let cos_t = (1.0 - sin_t * sin_t).sqrt();
            let outside = reflectance(cos_i, 1.0, n2);
            let inside = reflectance(cos_t, n2, 1.0);
            prop_assert!((outside - inside).abs() < 1e-13);
            prop_assert!((0.0..1.0).contains(&outside));
        }
    }
}
