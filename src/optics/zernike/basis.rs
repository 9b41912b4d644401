//! [`ZernikeBasis`]: the first `n_terms` Noll terms on a disk, evaluated with
//! Cartesian gradients.

use nalgebra::Complex;

use super::radial::{Layout, NONE};
use super::{ZernikeError, MAX_TERMS};

/// The Noll terms j = 1 ..= `n_terms` on the disk of `radius_mm` about
/// `center_mm` (world x, y, mm).
///
/// The layout of the recurrence is precomputed once, so evaluating all terms
/// costs O(`n_terms`) and allocates nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct ZernikeBasis {
    n_terms: usize,
    radius_mm: f64,
    center_mm: [f64; 2],
    pub(super) layout: Layout,
}

impl ZernikeBasis {
    /// Basis of the Noll terms 1 ..= `n_terms` normalised on the disk of
    /// radius `radius_mm` (mm) centred at `center_mm` (mm).
    ///
    /// # Errors
    /// [`ZernikeError::InvalidTermCount`] unless `1 <= n_terms <= MAX_TERMS`;
    /// [`ZernikeError::InvalidRadius`] unless `radius_mm` is finite and > 0;
    /// [`ZernikeError::InvalidCenter`] unless `center_mm` is finite.
    pub fn new(n_terms: usize, radius_mm: f64, center_mm: [f64; 2]) -> Result<Self, ZernikeError> {
        if n_terms == 0 || n_terms > MAX_TERMS {
            return Err(ZernikeError::InvalidTermCount {
                n_terms,
                max: MAX_TERMS,
            });
        }
        if !(radius_mm.is_finite() && radius_mm > 0.0) {
            return Err(ZernikeError::InvalidRadius { radius_mm });
        }
        if !center_mm.iter().all(|c| c.is_finite()) {
            return Err(ZernikeError::InvalidCenter { center_mm });
        }
        Ok(ZernikeBasis {
            n_terms,
            radius_mm,
            center_mm,
            layout: Layout::new(n_terms),
        })
    }

    /// Number of terms (Noll j = 1 ..= `n_terms`).
    pub fn n_terms(&self) -> usize {
        self.n_terms
    }

    /// Normalisation radius, mm: `rho = r / radius_mm`.
    pub fn radius_mm(&self) -> f64 {
        self.radius_mm
    }

    /// Disk centre (world x, y), mm.
    pub fn center_mm(&self) -> [f64; 2] {
        self.center_mm
    }

    /// Highest radial order n present in the basis.
    pub fn max_order(&self) -> u32 {
        super::indices::order_of(self.n_terms) as u32
    }

    /// Normalised coordinates `(X, Y) = ((x, y) - center_mm) / radius_mm`
    /// (dimensionless; `rho^2 = X^2 + Y^2`) of the world point `(x_mm, y_mm)`.
    #[inline]
    pub fn normalized(&self, x_mm: f64, y_mm: f64) -> (f64, f64) {
        let inv = 1.0 / self.radius_mm;
        (
            (x_mm - self.center_mm[0]) * inv,
            (y_mm - self.center_mm[1]) * inv,
        )
    }

    /// All basis values `Z_j(x, y)` (dimensionless) and their derivatives
    /// `dZ_j/dx`, `dZ_j/dy` (per mm) at the world point `(x_mm, y_mm)`.
    /// Slot k of each slice receives Noll j = k + 1. Valid everywhere, also
    /// outside the unit disk.
    ///
    /// # Errors
    /// [`ZernikeError::LengthMismatch`] unless all three slices hold exactly
    /// `n_terms` values (nothing is written then).
    pub fn eval_into(
        &self,
        x_mm: f64,
        y_mm: f64,
        values: &mut [f64],
        d_dx: &mut [f64],
        d_dy: &mut [f64],
    ) -> Result<(), ZernikeError> {
        self.check_len("values", values.len())?;
        self.check_len("d_dx", d_dx.len())?;
        self.check_len("d_dy", d_dy.len())?;
        self.fill_with_gradients(x_mm, y_mm, values, d_dx, d_dy);
        Ok(())
    }

    /// All basis values `Z_j(x, y)` (dimensionless) at the world point
    /// `(x_mm, y_mm)`; slot k receives Noll j = k + 1.
    ///
    /// # Errors
    /// [`ZernikeError::LengthMismatch`] unless `values` holds exactly
    /// `n_terms` values.
    pub fn eval_values_into(
        &self,
        x_mm: f64,
        y_mm: f64,
        values: &mut [f64],
    ) -> Result<(), ZernikeError> {
        self.check_len("values", values.len())?;
        self.fill_values(x_mm, y_mm, values);
        Ok(())
    }

    fn check_len(&self, what: &'static str, actual: usize) -> Result<(), ZernikeError> {
        if actual == self.n_terms {
            Ok(())
        } else {
            Err(ZernikeError::LengthMismatch {
                what,
                expected: self.n_terms,
                actual,
            })
        }
    }

    /// Values only; slices already checked to hold `n_terms` values.
    pub(super) fn fill_values(&self, x_mm: f64, y_mm: f64, values: &mut [f64]) {
        let (x, y) = self.normalized(x_mm, y_mm);
        let t = x * x + y * y;
        let w = Complex::new(x, y);
        let mut wm = Complex::new(1.0, 0.0); // (X + iY)^m
        let mut m_cur = 0;
        for col in &self.layout.columns {
            while m_cur < col.m {
                wm *= w;
                m_cur += 1;
            }
            let (mut q1, mut q2) = (1.0, 0.0); // Q_(k-1), Q_(k-2)
            for e in &self.layout.entries[col.start..col.end] {
                let s = e.step;
                let q = (s.a * t + s.b) * q1 - s.c * q2;
                (q2, q1) = (q1, q);
                let nq = e.norm * q;
                if e.idx_re != NONE {
                    values[e.idx_re] = nq * wm.re;
                }
                if e.idx_im != NONE {
                    values[e.idx_im] = nq * wm.im;
                }
            }
        }
    }

    /// Values and per-mm gradients; slices already checked.
    ///
    /// With `F = Q(X^2 + Y^2) (X + iY)^m`:
    /// `dF/dX = 2X Q' w^m + m Q w^(m-1)`, `dF/dY = 2Y Q' w^m + i m Q w^(m-1)`;
    /// cosine terms take the real part, sine terms the imaginary part.
    pub(super) fn fill_with_gradients(
        &self,
        x_mm: f64,
        y_mm: f64,
        values: &mut [f64],
        d_dx: &mut [f64],
        d_dy: &mut [f64],
    ) {
        let (x, y) = self.normalized(x_mm, y_mm);
        let t = x * x + y * y;
        let inv_r = 1.0 / self.radius_mm;
        let w = Complex::new(x, y);
        let (mut wm, mut wm1) = (Complex::new(1.0, 0.0), Complex::new(0.0, 0.0));
        let mut m_cur = 0;
        for col in &self.layout.columns {
            while m_cur < col.m {
                wm1 = wm;
                wm *= w;
                m_cur += 1;
            }
            let mf = f64::from(col.m);
            let (mut q1, mut q2, mut d1, mut d2) = (1.0, 0.0, 0.0, 0.0);
            for e in &self.layout.entries[col.start..col.end] {
                let s = e.step;
                let lin = s.a * t + s.b;
                let q = lin * q1 - s.c * q2;
                let dq = s.a * q1 + lin * d1 - s.c * d2;
                (q2, q1, d2, d1) = (q1, q, d1, dq);
                let a = wm * (2.0 * dq); // 2 Q' w^m
                let b = wm1 * (mf * q); // m Q w^(m-1)
                let g = e.norm * inv_r;
                if e.idx_re != NONE {
                    values[e.idx_re] = e.norm * q * wm.re;
                    d_dx[e.idx_re] = g * (x * a.re + b.re);
                    d_dy[e.idx_re] = g * (y * a.re - b.im);
                }
                if e.idx_im != NONE {
                    values[e.idx_im] = e.norm * q * wm.im;
                    d_dx[e.idx_im] = g * (x * a.im + b.im);
                    d_dy[e.idx_im] = g * (y * a.im + b.re);
                }
            }
        }
    }
}
