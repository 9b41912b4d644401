//! Where the PSM's focus stands when it is focused on a marked screen
//! pixel (`[[screen_point]]`): the mark itself on bare pixels, its image
//! through the cover glass otherwise, with the spread of the PSM's best
//! focus along its axis.
//!
//! The PSM looks along the stage's `z` axis (it is focused by moving the
//! stage along it). Seen through a parallel slab (thickness `t`, index `n`)
//! at an angle `θ` to its normal, a point `P` on the pixel plane has two
//! images (the slab is astigmatic off its normal):
//! - the **sagittal** one on the normal through `P`, at `δ(θ) = t (1 −
//!   cos θ / √(n² − sin² θ))` in front of it (each ray leaving `P` at `θ`
//!   emerges parallel to itself and appears to come from that point;
//!   `δ(0) = t (1 − 1/n)`, the paraxial focus shift);
//! - the **tangential** one further along the chief ray towards the viewer,
//!   by `s = δ'(θ) sin θ = t sin² θ (n² − 1) / (n² − sin² θ)^{3/2}` (the
//!   envelope of the rays in the plane of the normal and the axis).
//!
//! The PSM's best focus lies between the two; it is taken at their
//! midpoint, with a uniform spread over the interval (`σ = s / √12` along
//! the chief ray) added to the stage noise. On the paper's station (15°,
//! 1.8 mm at n = 1.52) `s` is 47 µm, so the reading along the PSM's axis is
//! known to 14 µm, across it to the stage noise.

use nalgebra::{Matrix3, Point3, Unit, Vector3};

use crate::optics::station::Screen;

/// Where the PSM's focus stands on a mark, and the spread of its best
/// focus beyond the stage's noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkFocus {
    /// The focus, world frame, mm.
    pub world_mm: Point3<f64>,
    /// Covariance of where the best focus lies (astigmatism), mm².
    pub focus_cov_mm2: Matrix3<f64>,
}

/// The PSM's focus on screen coordinate `(u, v)` for a PSM whose axis
/// points along `axis` (world frame, from the element towards the screen).
pub fn mark_focus(screen: &Screen, axis: &Unit<Vector3<f64>>, u: f64, v: f64) -> MarkFocus {
    let p = screen.world_point(u, v);
    let Some(g) = &screen.cover_glass else {
        return MarkFocus {
            world_mm: p,
            focus_cov_mm2: Matrix3::zeros(),
        };
    };
    // The chief ray from the mark to the PSM and the normal on its side.
    let d = -axis.into_inner();
    let n0 = screen.normal().into_inner();
    let n_v = if n0.dot(&d) >= 0.0 { n0 } else { -n0 };
    let cos = n_v.dot(&d).clamp(-1.0, 1.0);
    let sin2 = 1.0 - cos * cos;
    let (t, n) = (g.thickness_mm, g.refractive_index);
    let root = (n * n - sin2).sqrt();
    let delta = t * (1.0 - cos / root);
    let s = t * sin2 * (n * n - 1.0) / root.powi(3);
    let world_mm = p + delta * n_v + 0.5 * s * d;
    MarkFocus {
        world_mm,
        focus_cov_mm2: (s * s / 12.0) * d * d.transpose(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::station::CoverGlass;

    fn screen(tilt_deg: f64) -> Screen {
        let r = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), tilt_deg.to_radians());
        Screen {
            width: 100,
            height: 100,
            pixel_pitch_mm: 0.27,
            origin_mm: Point3::new(0.0, 0.0, 800.0),
            u_axis: Unit::new_normalize(r * Vector3::x()),
            v_axis: Unit::new_normalize(r * -Vector3::y()),
            cover_glass: Some(CoverGlass {
                thickness_mm: 1.8,
                refractive_index: 1.52,
            }),
        }
    }

    /// Where two rays leaving the mark at `θ ± ε` in the tangential plane,
    /// traced through the slab by Snell's law, meet once extended back
    /// (the tangential image), and where the ray at `θ` crosses the normal
    /// through the mark (the sagittal image): the oracle of the closed
    /// forms, in the plane's coordinates (lateral, along the normal
    /// towards the viewer) from the mark, then in the world.
    fn traced_images(s: &Screen, theta: f64) -> (Point3<f64>, Point3<f64>) {
        let g = s.cover_glass.unwrap();
        let (t, n) = (g.thickness_mm, g.refractive_index);
        let p = s.world_point(50.0, 50.0);
        let n0 = s.normal();
        let n_v = if n0.z < 0.0 { n0 } else { -n0 };
        let chief = -Vector3::z();
        let lateral = (chief - chief.dot(&n_v) * n_v.into_inner()).normalize();
        // The ray leaving the slab at air angle `a`: exit point, direction.
        let ray = |a: f64| {
            let inside = (a.sin() / n).asin();
            ([t * inside.tan(), t], [a.sin(), a.cos()])
        };
        let eps = 1e-5;
        let ((p1, d1), (p2, d2)) = (ray(theta - eps), ray(theta + eps));
        let cross = |a: [f64; 2], b: [f64; 2]| a[0] * b[1] - a[1] * b[0];
        // p1 + k d1 on the line p2 + k' d2; d1 × d2 = sin(−2ε), exactly.
        let k = cross([p2[0] - p1[0], p2[1] - p1[1]], d2) / (-2.0 * eps).sin();
        let tangential = [p1[0] + k * d1[0], p1[1] + k * d1[1]];
        let (e, d) = ray(theta);
        let back = e[0] / d[0];
        let sagittal = [0.0, e[1] - back * d[1]];
        let world = |q: [f64; 2]| p + q[0] * lateral + q[1] * n_v.into_inner();
        (world(tangential), world(sagittal))
    }

    #[test]
    fn the_focus_is_midway_between_the_traced_images() {
        // The screen tilted by 15° and 3°; the PSM looks along world +z.
        for tilt in [15.0_f64, 3.0] {
            let s = screen(tilt);
            let axis = Vector3::z_axis();
            let f = mark_focus(&s, &axis, 50.0, 50.0);
            let (t, sg) = traced_images(&s, tilt.to_radians());
            let mid = nalgebra::center(&t, &sg);
            // Rays 2e-5 rad apart cross at the envelope's point to O(ε²)
            // (1e-10 of the 0.05 mm), and rounding (1e-16 over sin 2ε) adds
            // 1e-11 mm: 1e-8 mm covers both with room.
            let off = (f.world_mm - mid).norm();
            assert!(off < 1e-8, "{tilt}°: {off}");
            let spread = (t - sg).norm();
            let sigma = f.focus_cov_mm2.trace().sqrt();
            assert!(
                (sigma - spread / 12f64.sqrt()).abs() < 1e-8,
                "{sigma} {spread}"
            );
        }
    }

    #[test]
    fn on_the_normal_the_focus_is_the_paraxial_shift() {
        let s = screen(0.0);
        let f = mark_focus(&s, &Vector3::z_axis(), 50.0, 50.0);
        let p = s.world_point(50.0, 50.0);
        // t (1 − 1/n) towards the viewer (−z), no astigmatism.
        let want = 1.8 * (1.0 - 1.0 / 1.52);
        assert!(((p - f.world_mm).z - want).abs() < 1e-12);
        assert!(f.focus_cov_mm2.norm() < 1e-20);
        let bare = Screen {
            cover_glass: None,
            ..s
        };
        assert_eq!(
            mark_focus(&bare, &Vector3::z_axis(), 50.0, 50.0).world_mm,
            p
        );
    }
}
