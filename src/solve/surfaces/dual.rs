//! Forward-mode dual numbers: a value and its first derivatives with respect
//! to `N` local surface perturbations. The inverse ray tracer evaluates one
//! light path in these, so one trace gives the exact Jacobian of the screen
//! point with respect to the local height and slopes at every surface the
//! path touches.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A value with its gradient over `N` parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// `∂v/∂p_k`.
    pub g: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// A constant (no dependence on the parameters).
    pub fn c(v: f64) -> Self {
        Dual { v, g: [0.0; N] }
    }

    /// Parameter `k` itself, at value `v`.
    pub fn param(v: f64, k: usize) -> Self {
        let mut g = [0.0; N];
        g[k] = 1.0;
        Dual { v, g }
    }

    /// Square root (value > 0 assumed by the callers: norms and cosines).
    pub fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let k = 0.5 / s;
        Dual {
            v: s,
            g: self.g.map(|x| x * k),
        }
    }

    /// Sine (angles in radians).
    pub fn sin(self) -> Self {
        let c = self.v.cos();
        Dual {
            v: self.v.sin(),
            g: self.g.map(|x| x * c),
        }
    }

    /// Cosine (angles in radians).
    pub fn cos(self) -> Self {
        let s = -self.v.sin();
        Dual {
            v: self.v.cos(),
            g: self.g.map(|x| x * s),
        }
    }

    /// `self · k` for a plain number.
    pub fn scale(self, k: f64) -> Self {
        Dual {
            v: self.v * k,
            g: self.g.map(|x| x * k),
        }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        let mut g = self.g;
        for (a, b) in g.iter_mut().zip(o.g) {
            *a += b;
        }
        Dual { v: self.v + o.v, g }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        let mut g = self.g;
        for (a, b) in g.iter_mut().zip(o.g) {
            *a -= b;
        }
        Dual { v: self.v - o.v, g }
    }
}

// The product rule adds: not a slip of the operator.
#[allow(clippy::suspicious_arithmetic_impl)]
impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        let g = std::array::from_fn(|k| self.g[k] * o.v + self.v * o.g[k]);
        Dual { v: self.v * o.v, g }
    }
}

#[allow(clippy::suspicious_arithmetic_impl)]
impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let q = self.v * inv;
        let g = std::array::from_fn(|k| (self.g[k] - q * o.g[k]) * inv);
        Dual { v: q, g }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    fn neg(self) -> Self {
        self.scale(-1.0)
    }
}

/// A 3-vector of duals.
pub type V3<const N: usize> = [Dual<N>; 3];

/// A constant vector.
pub fn v3c<const N: usize>(x: [f64; 3]) -> V3<N> {
    x.map(Dual::c)
}

/// Value part.
pub fn v3val<const N: usize>(a: &V3<N>) -> [f64; 3] {
    [a[0].v, a[1].v, a[2].v]
}

/// `a · b`.
pub fn dot<const N: usize>(a: &V3<N>, b: &V3<N>) -> Dual<N> {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a + s b`.
pub fn axpy<const N: usize>(a: &V3<N>, s: Dual<N>, b: &V3<N>) -> V3<N> {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// `s a`.
pub fn scale<const N: usize>(s: Dual<N>, a: &V3<N>) -> V3<N> {
    [s * a[0], s * a[1], s * a[2]]
}

/// `a × b`.
pub fn cross<const N: usize>(a: &V3<N>, b: &V3<N>) -> V3<N> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// A 3 × 3 matrix of duals, row-major.
pub type M3<const N: usize> = [[Dual<N>; 3]; 3];

/// `m v`.
pub fn mat_vec<const N: usize>(m: &M3<N>, v: &V3<N>) -> V3<N> {
    m.map(|row| dot(&row, v))
}

/// `a b`.
pub fn mat_mul<const N: usize>(a: &M3<N>, b: &M3<N>) -> M3<N> {
    std::array::from_fn(|r| {
        std::array::from_fn(|c| a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c])
    })
}

/// `mᵀ`.
pub fn transpose<const N: usize>(m: &M3<N>) -> M3<N> {
    std::array::from_fn(|r| std::array::from_fn(|c| m[c][r]))
}

/// `a / ‖a‖`.
pub fn normalize<const N: usize>(a: &V3<N>) -> V3<N> {
    let inv = Dual::c(1.0) / dot(a, a).sqrt();
    scale(inv, a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Derivatives of a composite expression against central differences;
    /// the step 1e-6 gives truncation ~1e-12 and round-off ~1e-10 relative.
    #[test]
    fn derivatives_match_finite_differences() {
        let f = |x: Dual<2>, y: Dual<2>| (x * y + Dual::c(3.0)).sqrt() / (x - y.scale(0.5));
        let (x0, y0) = (1.3, 0.7);
        let d = f(Dual::param(x0, 0), Dual::param(y0, 1));
        let h = 1e-6;
        let fx = |x: f64, y: f64| f(Dual::c(x), Dual::c(y)).v;
        let dx = (fx(x0 + h, y0) - fx(x0 - h, y0)) / (2.0 * h);
        let dy = (fx(x0, y0 + h) - fx(x0, y0 - h)) / (2.0 * h);
        assert!((d.g[0] - dx).abs() < 1e-8 * dx.abs().max(1.0));
        assert!((d.g[1] - dy).abs() < 1e-8 * dy.abs().max(1.0));
    }

    /// sin and cos: derivatives are the closed forms cos and −sin.
    #[test]
    fn trigonometric_derivatives_are_the_closed_forms() {
        for x0 in [-2.0, 0.3, 1.1] {
            let (s, c) = (Dual::<1>::param(x0, 0).sin(), Dual::<1>::param(x0, 0).cos());
            assert_eq!((s.v, s.g[0]), (x0.sin(), x0.cos()));
            assert_eq!((c.v, c.g[0]), (x0.cos(), -x0.sin()));
        }
    }
}
