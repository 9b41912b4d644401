//! The lens's distortion in OpenCV's Brown–Conrady model (station v2,
//! `interchange.md`): the forward map from the ideal image plane to the
//! distorted one, its Jacobian, and its inverse by Newton.
//!
//! Written by hand: the inverse is a two-unknown Newton iteration on a
//! polynomial, with a convergence guarantee (the writer's monotonicity
//! condition) that a general root finder would not know to use.

/// Radial `k1, k2, k3` and tangential `p1, p2` coefficients, acting on the
/// normalised image coordinates `x' = X/Z`, `y' = Y/Z` of the camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distortion {
    /// Radial k1, k2, k3.
    pub k: [f64; 3],
    /// Tangential p1, p2.
    pub p: [f64; 2],
}

/// Stop Newton when the distorted point is matched to this, in normalised
/// image units. On the paper's lens (F ≈ 4 270 px per unit) it is 4e-11 px,
/// seven orders below the solvers' 1e-4 px resolution and a few hundred
/// rounding errors of the coordinates themselves.
const INVERSE_TOL: f64 = 1e-14;

/// Newton steps allowed; monotone maps converge quadratically in 3–6.
const MAX_STEPS: usize = 60;

impl Distortion {
    /// Whether every coefficient is zero.
    pub fn is_zero(&self) -> bool {
        self.k.iter().chain(&self.p).all(|&c| c == 0.0)
    }

    /// The radial factor `1 + k1 r² + k2 r⁴ + k3 r⁶` at `r²`.
    pub fn radial(&self, r2: f64) -> f64 {
        let [k1, k2, k3] = self.k;
        1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    }

    /// `d/dr [r (1 + k1 r² + k2 r⁴ + k3 r⁶)]` at `r²`: the radial map's slope.
    pub fn radial_slope(&self, r2: f64) -> f64 {
        let [k1, k2, k3] = self.k;
        1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
    }

    /// `(x'', y'')` of the ideal `(x', y')`, the spec's formula.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [p1, p2] = self.p;
        let r2 = x * x + y * y;
        let f = self.radial(r2);
        (
            x * f + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * f + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// The Jacobian `∂(x'', y'') / ∂(x', y')`, row-major.
    pub fn jacobian(&self, x: f64, y: f64) -> [[f64; 2]; 2] {
        let [k1, k2, k3] = self.k;
        let [p1, p2] = self.p;
        let r2 = x * x + y * y;
        let f = self.radial(r2);
        // d f / d(r²)
        let df = k1 + r2 * (2.0 * k2 + r2 * 3.0 * k3);
        [
            [
                f + 2.0 * x * x * df + 2.0 * p1 * y + 6.0 * p2 * x,
                2.0 * x * y * df + 2.0 * p1 * x + 2.0 * p2 * y,
            ],
            [
                2.0 * x * y * df + 2.0 * p1 * x + 2.0 * p2 * y,
                f + 2.0 * y * y * df + 6.0 * p1 * y + 2.0 * p2 * x,
            ],
        ]
    }

    /// The ideal `(x', y')` that distorts to `(xd, yd)`: Newton from the
    /// distorted point, halving a step that does not reduce the mismatch.
    /// `None` when it does not converge (outside the region where the map
    /// is invertible).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        let (mut x, mut y) = (xd, yd);
        let mismatch = |x: f64, y: f64| {
            let (a, b) = self.distort(x, y);
            (a - xd, b - yd)
        };
        let (mut ex, mut ey) = mismatch(x, y);
        for _ in 0..MAX_STEPS {
            let e = ex.hypot(ey);
            if e <= INVERSE_TOL * (1.0 + xd.hypot(yd)) {
                return Some((x, y));
            }
            let j = self.jacobian(x, y);
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if !det.is_finite() || det.abs() < 1e-300 {
                return None;
            }
            let dx = (j[1][1] * ex - j[0][1] * ey) / det;
            let dy = (-j[1][0] * ex + j[0][0] * ey) / det;
            let mut step = 1.0;
            loop {
                let (nx, ny) = (x - step * dx, y - step * dy);
                let (fx, fy) = mismatch(nx, ny);
                if fx.hypot(fy) < e || step < 1e-6 {
                    (x, y, ex, ey) = (nx, ny, fx, fy);
                    break;
                }
                step *= 0.5;
            }
        }
        let ok = ex.hypot(ey) <= INVERSE_TOL * (1.0 + xd.hypot(yd));
        ok.then_some((x, y))
    }

    /// Why the inverse is not unique over a sensor whose farthest corner
    /// lies at distorted radius `rd_max` (normalised units), or `None` when
    /// it is: the radial map `r (1 + k1 r² + k2 r⁴ + k3 r⁶)` must increase
    /// from 0 until it passes `rd_max` (the writer's guarantee in the spec).
    /// Checked on 4 096 radii up to the first that passes `rd_max`, with the
    /// slope's sign at each: a polynomial of degree 6 in r changes sign at
    /// most 3 times, far coarser than the grid.
    pub fn not_monotone_below(&self, rd_max: f64) -> Option<String> {
        // The ideal radius cannot exceed the distorted one by more than the
        // radial factor allows; search up to 4× the distorted radius.
        let r_end = 4.0 * rd_max.max(1e-9);
        const STEPS: usize = 4096;
        for s in 0..=STEPS {
            let r = r_end * s as f64 / STEPS as f64;
            let r2 = r * r;
            if self.radial_slope(r2) <= 0.0 {
                return Some(format!(
                    "the radial map r(1 + k1 r² + k2 r⁴ + k3 r⁶) stops increasing at r = {r:.4} \
                     (normalised), before reaching the sensor's corner at distorted radius \
                     {rd_max:.4}: its inverse is not unique over the sensor"
                ));
            }
            if r * self.radial(r2) >= rd_max {
                return None;
            }
        }
        Some(format!(
            "the radial map never reaches the sensor's corner at distorted radius {rd_max:.4}"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens() -> Distortion {
        Distortion {
            k: [-0.12, 0.03, -0.004],
            p: [0.0004, -0.0002],
        }
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let d = lens();
        let (x, y, h) = (0.21, -0.13, 1e-6);
        let j = d.jacobian(x, y);
        let (a, b) = (d.distort(x + h, y), d.distort(x - h, y));
        let (c, e) = (d.distort(x, y + h), d.distort(x, y - h));
        // Central differences: error ~ h² × third derivative ≈ 1e-12.
        assert!((j[0][0] - (a.0 - b.0) / (2.0 * h)).abs() < 1e-8);
        assert!((j[1][0] - (a.1 - b.1) / (2.0 * h)).abs() < 1e-8);
        assert!((j[0][1] - (c.0 - e.0) / (2.0 * h)).abs() < 1e-8);
        assert!((j[1][1] - (c.1 - e.1) / (2.0 * h)).abs() < 1e-8);
    }

    #[test]
    fn undistort_round_trips_over_a_wide_field() {
        let d = lens();
        let mut worst = 0.0_f64;
        for a in -20..=20 {
            for b in -15..=15 {
                let (x, y) = (f64::from(a) * 0.02, f64::from(b) * 0.02);
                let (xd, yd) = d.distort(x, y);
                let (u, v) = d.undistort(xd, yd).expect("converges");
                worst = worst.max((u - x).hypot(v - y));
            }
        }
        // The map's slope is ≥ 0.85 on this field, so a mismatch of
        // INVERSE_TOL × (1 + r) is an error below 3e-14.
        assert!(worst < 3e-14, "worst round-trip error {worst:e}");
    }

    #[test]
    fn fold_over_is_reported() {
        let strong = Distortion {
            k: [-0.9, 0.0, 0.0],
            p: [0.0; 2],
        };
        // The slope 1 − 2.7 r² vanishes at r = 0.61, where r f(r) = 0.41.
        assert!(strong.not_monotone_below(0.3).is_none());
        assert!(strong.not_monotone_below(0.5).is_some());
    }
}
