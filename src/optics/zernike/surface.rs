//! [`ZernikeSurface`]: `W = sum_j c_j Z_j`, evaluated in O(terms) without
//! allocation for the ray tracer's inner loop.
//!
//! The coefficients are folded into a table of recurrence steps laid out by
//! (group of `LANES` azimuthal orders, k, lane): the recurrences of the
//! columns in a group are independent, so they run side by side (SIMD lanes /
//! instruction-level parallelism) instead of one long dependency chain.

use nalgebra::Complex;

use super::radial::NONE;
use super::{ZernikeBasis, ZernikeError, MM_PER_NM};

/// Azimuthal orders evaluated side by side.
const LANES: usize = 4;

/// Step k of the recurrences of one group, one lane per azimuthal order, with
/// the coefficients folded in: `w_re = c_cos * norm`, `w_im = c_sin * norm`
/// (nm). Lanes past the end of their column hold zeros (Q becomes 0 there and
/// weighs nothing).
#[derive(Debug, Clone, PartialEq)]
struct Packed {
    a: [f64; LANES],
    b: [f64; LANES],
    c: [f64; LANES],
    w_re: [f64; LANES],
    w_im: [f64; LANES],
}

/// Up to `LANES` columns of increasing m sharing one run of [`Packed`] steps.
/// Unused lanes repeat the last m with zero weights.
#[derive(Debug, Clone, PartialEq)]
struct Group {
    m: [u32; LANES],
    start: usize,
    end: usize,
}

/// Per-lane sums `S = sum_k w Q_k` and `S' = sum_k w Q_k'` of one group.
struct Sums {
    re: [f64; LANES],
    im: [f64; LANES],
    d_re: [f64; LANES],
    d_im: [f64; LANES],
}

/// A surface `W(x, y) = sum_j c_j Z_j(x, y)` with `c_j` in nanometres on a
/// [`ZernikeBasis`]. Heights come back in mm, gradients in mm/mm.
///
/// The coefficients are folded into a precomputed table at construction, so
/// they are read-only: build a new surface to change them.
#[derive(Debug, Clone, PartialEq)]
pub struct ZernikeSurface {
    basis: ZernikeBasis,
    coefficients_nm: Vec<f64>,
    groups: Vec<Group>,
    table: Vec<Packed>,
}

impl ZernikeSurface {
    /// The surface with `coefficients_nm[k]` (nm) on Noll term j = k + 1 of
    /// `basis`.
    ///
    /// # Errors
    /// [`ZernikeError::LengthMismatch`] unless there are exactly
    /// `basis.n_terms()` coefficients; [`ZernikeError::NonFinite`] for a NaN
    /// or infinite coefficient.
    pub fn new(basis: ZernikeBasis, coefficients_nm: Vec<f64>) -> Result<Self, ZernikeError> {
        if coefficients_nm.len() != basis.n_terms() {
            return Err(ZernikeError::LengthMismatch {
                what: "coefficients_nm",
                expected: basis.n_terms(),
                actual: coefficients_nm.len(),
            });
        }
        if let Some(index) = coefficients_nm.iter().position(|c| !c.is_finite()) {
            return Err(ZernikeError::NonFinite {
                what: "coefficients_nm",
                index,
            });
        }
        let (groups, table) = fold(&basis, &coefficients_nm);
        Ok(ZernikeSurface {
            basis,
            coefficients_nm,
            groups,
            table,
        })
    }

    /// The flat surface `W = 0` (a single zero piston term) on the disk of
    /// `radius_mm` about `center_mm` (mm).
    ///
    /// # Errors
    /// [`ZernikeError::InvalidRadius`] / [`ZernikeError::InvalidCenter`] as
    /// for [`ZernikeBasis::new`].
    pub fn flat(radius_mm: f64, center_mm: [f64; 2]) -> Result<Self, ZernikeError> {
        ZernikeSurface::new(ZernikeBasis::new(1, radius_mm, center_mm)?, vec![0.0])
    }

    /// True when every coefficient is zero (`W = 0` everywhere).
    pub fn is_flat(&self) -> bool {
        self.coefficients_nm.iter().all(|&c| c == 0.0)
    }

    /// Number of coefficients (= `basis().n_terms()`).
    pub fn n_terms(&self) -> usize {
        self.coefficients_nm.len()
    }

    /// The basis the coefficients refer to.
    pub fn basis(&self) -> &ZernikeBasis {
        &self.basis
    }

    /// Coefficients in nm; index k holds Noll j = k + 1.
    pub fn coefficients_nm(&self) -> &[f64] {
        &self.coefficients_nm
    }

    /// Height `W(x, y)` in mm at the world point `(x_mm, y_mm)`; the
    /// polynomial also outside the unit disk. No allocation; a NaN coordinate
    /// gives NaN.
    pub fn height_mm(&self, x_mm: f64, y_mm: f64) -> f64 {
        let (x, y) = self.basis.normalized(x_mm, y_mm);
        let t = x * x + y * y;
        let w = Complex::new(x, y);
        let mut wm = Complex::new(1.0, 0.0);
        let mut m_cur = 0;
        let mut h = 0.0;
        for g in &self.groups {
            let s = group_values(&self.table[g.start..g.end], t);
            for l in 0..LANES {
                while m_cur < g.m[l] {
                    wm *= w;
                    m_cur += 1;
                }
                h += s.re[l] * wm.re + s.im[l] * wm.im;
            }
        }
        h * MM_PER_NM
    }

    /// Height (mm) and gradient `(dW/dx, dW/dy)` (dimensionless, mm/mm) at the
    /// world point `(x_mm, y_mm)`. Regular at the disk centre, valid outside
    /// the unit disk. No allocation; cost O(`n_terms`). Inputs are not
    /// checked (inner loop): a NaN coordinate gives NaN results.
    pub fn height_and_gradient(&self, x_mm: f64, y_mm: f64) -> (f64, f64, f64) {
        let (x, y) = self.basis.normalized(x_mm, y_mm);
        let t = x * x + y * y;
        let w = Complex::new(x, y);
        let (mut wm, mut wm1) = (Complex::new(1.0, 0.0), Complex::new(0.0, 0.0));
        let mut m_cur = 0;
        let (mut h, mut gx, mut gy) = (0.0, 0.0, 0.0);
        for g in &self.groups {
            let sums = group_gradients(&self.table[g.start..g.end], t);
            for l in 0..LANES {
                while m_cur < g.m[l] {
                    wm1 = wm;
                    wm *= w;
                    m_cur += 1;
                }
                // Column term = Re(S w^m) with S = sum_k (w_re - i w_im) Q_k.
                let s = Complex::new(sums.re[l], -sums.im[l]);
                let ds = Complex::new(sums.d_re[l], -sums.d_im[l]);
                let a = ds * wm; // S' w^m
                let b = s * wm1 * f64::from(m_cur); // m S w^(m-1)
                h += (s * wm).re;
                gx += 2.0 * x * a.re + b.re;
                gy += 2.0 * y * a.re - b.im;
            }
        }
        let g = MM_PER_NM / self.basis.radius_mm();
        (h * MM_PER_NM, gx * g, gy * g)
    }
}

/// Run the recurrences of one group: weighted sums of Q_k.
#[inline(always)]
fn group_values(steps: &[Packed], t: f64) -> Sums {
    let (mut q1, mut q2) = ([1.0; LANES], [0.0; LANES]);
    let (mut re, mut im) = ([0.0; LANES], [0.0; LANES]);
    for e in steps {
        for l in 0..LANES {
            let q = (e.a[l] * t + e.b[l]) * q1[l] - e.c[l] * q2[l];
            (q2[l], q1[l]) = (q1[l], q);
            re[l] += e.w_re[l] * q;
            im[l] += e.w_im[l] * q;
        }
    }
    Sums {
        re,
        im,
        d_re: [0.0; LANES],
        d_im: [0.0; LANES],
    }
}

/// Run the recurrences of one group: weighted sums of Q_k and of dQ_k/dt.
#[inline(always)]
fn group_gradients(steps: &[Packed], t: f64) -> Sums {
    let (mut q1, mut q2) = ([1.0; LANES], [0.0; LANES]);
    let (mut d1, mut d2) = ([0.0; LANES], [0.0; LANES]);
    let (mut re, mut im) = ([0.0; LANES], [0.0; LANES]);
    let (mut d_re, mut d_im) = ([0.0; LANES], [0.0; LANES]);
    for e in steps {
        for l in 0..LANES {
            let lin = e.a[l] * t + e.b[l];
            let q = lin * q1[l] - e.c[l] * q2[l];
            let dq = e.a[l] * q1[l] + lin * d1[l] - e.c[l] * d2[l];
            (q2[l], q1[l], d2[l], d1[l]) = (q1[l], q, d1[l], dq);
            re[l] += e.w_re[l] * q;
            im[l] += e.w_im[l] * q;
            d_re[l] += e.w_re[l] * dq;
            d_im[l] += e.w_im[l] * dq;
        }
    }
    Sums { re, im, d_re, d_im }
}

/// One column of the folded table: its m and its steps
/// `(a, b, c, w_re, w_im)`, trailing zero-weight steps dropped.
type FoldedColumn = (u32, Vec<[f64; 5]>);

/// Fold the coefficients into grouped steps, dropping all-zero columns.
fn fold(basis: &ZernikeBasis, c: &[f64]) -> (Vec<Group>, Vec<Packed>) {
    let coef = |i: usize| if i == NONE { 0.0 } else { c[i] };
    let mut columns: Vec<FoldedColumn> = Vec::new();
    for col in &basis.layout.columns {
        let mut steps: Vec<[f64; 5]> = basis.layout.entries[col.start..col.end]
            .iter()
            .map(|e| {
                let s = e.step;
                [
                    s.a,
                    s.b,
                    s.c,
                    coef(e.idx_re) * e.norm,
                    coef(e.idx_im) * e.norm,
                ]
            })
            .collect();
        while steps.last().is_some_and(|s| s[3] == 0.0 && s[4] == 0.0) {
            steps.pop();
        }
        if !steps.is_empty() {
            columns.push((col.m, steps));
        }
    }
    let (mut groups, mut table) = (Vec::new(), Vec::new());
    for chunk in columns.chunks(LANES) {
        let len = chunk.iter().map(|(_, s)| s.len()).max().unwrap_or(0);
        let last_m = chunk[chunk.len() - 1].0;
        let m = std::array::from_fn(|l| chunk.get(l).map_or(last_m, |(m, _)| *m));
        let start = table.len();
        for k in 0..len {
            let step = |l: usize, f: usize| {
                chunk
                    .get(l)
                    .and_then(|(_, s)| s.get(k))
                    .map_or(0.0, |s| s[f])
            };
            table.push(Packed {
                a: std::array::from_fn(|l| step(l, 0)),
                b: std::array::from_fn(|l| step(l, 1)),
                c: std::array::from_fn(|l| step(l, 2)),
                w_re: std::array::from_fn(|l| step(l, 3)),
                w_im: std::array::from_fn(|l| step(l, 4)),
            });
        }
        groups.push(Group {
            m,
            start,
            end: table.len(),
        });
    }
    (groups, table)
}
