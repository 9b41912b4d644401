//! Radial polynomials by the Jacobi three-term recurrence, and the evaluation
//! layout shared by [`super::ZernikeBasis`] and [`super::ZernikeSurface`].
//!
//! `R_n^m(rho) = rho^m Q_k(t)` with `t = rho^2`, `k = (n - m)/2` and
//! `Q_k(t) = (-1)^k P_k^(m,0)(1 - 2t) = P_k^(0,m)(2t - 1)`, a Jacobi
//! polynomial. In t the recurrence reads
//! `Q_k = (a_k t + b_k) Q_(k-1) - c_k Q_(k-2)`, `Q_0 = 1`, and is stable on
//! [0, 1] (orthogonal polynomials) and outside it (dominant solution). Its
//! derivative follows by differentiating the recurrence. No factorials.

use super::indices::{noll_of, order_of};
use super::{ZernikeError, MAX_RADIAL_ORDER};

/// Marks a (n, m) slot that is not part of the basis.
pub(super) const NONE: usize = usize::MAX;

/// Coefficients of one recurrence step `Q_k = (a t + b) Q_(k-1) - c Q_(k-2)`.
///
/// Step k = 0 is `(0, 1, 0)`: started from a fictitious `Q_(-1) = 1` it yields
/// `Q_0 = 1` and `Q_0' = 0`, so every k runs the same branch-free code.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Step {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

impl Step {
    /// The step producing `Q_k` for azimuthal order `m` (Jacobi
    /// `P_k^(0,m)(x)` recurrence with `x = 2t - 1`).
    pub(super) fn new(m: u32, k: u32) -> Step {
        let mf = f64::from(m);
        match k {
            0 => Step {
                a: 0.0,
                b: 1.0,
                c: 0.0,
            },
            // P_1^(0,m)(2t-1) = (m+2) t - (m+1)
            1 => Step {
                a: mf + 2.0,
                b: -(mf + 1.0),
                c: 0.0,
            },
            _ => {
                let kf = f64::from(k);
                let s = 2.0 * kf + mf;
                let d = 2.0 * kf * (kf + mf) * (s - 2.0);
                Step {
                    a: 2.0 * (s - 1.0) * s * (s - 2.0) / d,
                    b: -(s - 1.0) * (s * (s - 2.0) + mf * mf) / d,
                    c: 2.0 * (kf - 1.0) * (kf + mf - 1.0) * s / d,
                }
            }
        }
    }
}

/// Radial polynomial `R_n^m(rho)` (`m` is |m|; sign irrelevant here).
///
/// Exact to f64 rounding for all supported orders, also for `rho > 1`
/// where the polynomial simply keeps growing (no clamping).
///
/// # Errors
/// [`ZernikeError::InvalidOrder`] unless `m <= n`, `n - m` even and
/// `n <= MAX_RADIAL_ORDER`.
pub fn radial_polynomial(n: u32, m: u32, rho: f64) -> Result<f64, ZernikeError> {
    if m > n || (n - m) % 2 != 0 || n > MAX_RADIAL_ORDER {
        return Err(ZernikeError::InvalidOrder {
            n,
            m: i32::try_from(m).unwrap_or(i32::MAX),
        });
    }
    let t = rho * rho;
    let (mut q1, mut q2) = (1.0, 0.0);
    for k in 0..=(n - m) / 2 {
        let s = Step::new(m, k);
        let q = (s.a * t + s.b) * q1 - s.c * q2;
        q2 = q1;
        q1 = q;
    }
    // m <= MAX_RADIAL_ORDER, fits i32.
    Ok(q1 * rho.powi(m as i32))
}

/// One (n, m) slot of the layout: recurrence step, normalisation and the
/// coefficient-vector indices of its cosine (`idx_re`, also m = 0) and sine
/// (`idx_im`) terms, [`NONE`] when outside the basis.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Entry {
    pub step: Step,
    pub norm: f64,
    pub idx_re: usize,
    pub idx_im: usize,
}

/// A run of entries of one azimuthal order m, k = 0, 1, ... in order.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Column {
    pub m: u32,
    pub start: usize,
    pub end: usize,
}

/// The basis laid out by (m, k): columns in increasing m, each a contiguous
/// run of entries in increasing k.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Layout {
    pub columns: Vec<Column>,
    pub entries: Vec<Entry>,
}

impl Layout {
    /// Layout of Noll terms 1 ..= `n_terms` (`n_terms >= 1`, validated).
    pub(super) fn new(n_terms: usize) -> Layout {
        let n_max = order_of(n_terms) as u32;
        let index = |n: u32, m: i32| {
            let j = noll_of(u64::from(n), m) as usize;
            if j <= n_terms {
                j - 1
            } else {
                NONE
            }
        };
        let mut columns = Vec::new();
        let mut entries = Vec::new();
        for m in 0..=n_max {
            let start = entries.len();
            for k in 0..=(n_max - m) / 2 {
                let n = m + 2 * k;
                let (idx_re, idx_im) = if m == 0 {
                    (index(n, 0), NONE)
                } else {
                    (index(n, m as i32), index(n, -(m as i32)))
                };
                if idx_re == NONE && idx_im == NONE {
                    break; // higher n of this m have larger j: all absent
                }
                let nf = f64::from(n);
                let norm = if m == 0 {
                    (nf + 1.0).sqrt()
                } else {
                    (2.0 * (nf + 1.0)).sqrt()
                };
                let step = Step::new(m, k);
                entries.push(Entry {
                    step,
                    norm,
                    idx_re,
                    idx_im,
                });
            }
            if entries.len() > start {
                columns.push(Column {
                    m,
                    start,
                    end: entries.len(),
                });
            }
        }
        Layout { columns, entries }
    }
}
