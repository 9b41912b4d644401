//! Noll indexing and evaluation of Zernike polynomials with gradients by
//! Jacobi recurrences (no factorial sums), exact to high radial order.
//!
//! `R_n^m(ρ) cos mθ = Q(t) Re (X + iY)^m` and `R_n^m(ρ) sin mθ = Q(t) Im (X + iY)^m`
//! with `t = ρ² = X² + Y²`, `Q(t) = (−1)^k P_k^{(m,0)}(1 − 2t)`, `k = (n − m)/2`.
//! Both factors are polynomials in X, Y, so the gradient
//! `∂/∂X [Q (X+iY)^m] = 2X Q' (X+iY)^m + m Q (X+iY)^{m−1}` (and `i m` for ∂/∂Y)
//! has no 1/ρ and is regular at the centre.

use super::ZernikeError;

/// Noll index j (≥ 1) → radial order n and signed azimuthal order m
/// (m > 0: cos mθ, m < 0: sin |m|θ, 0: rotationally symmetric).
///
/// # Errors
/// [`ZernikeError::InvalidIndex`] for j = 0.
pub fn noll_to_nm(j: usize) -> Result<(u32, i32), ZernikeError> {
    if j == 0 {
        return Err(ZernikeError::InvalidIndex { j });
    }
    // Largest n with n(n+1)/2 < j.
    let mut n = (((8.0 * (j - 1) as f64 + 1.0).sqrt() - 1.0) / 2.0) as usize;
    while n * (n + 1) / 2 >= j {
        n -= 1;
    }
    while (n + 1) * (n + 2) / 2 < j {
        n += 1;
    }
    let p = j - n * (n + 1) / 2; // 1-based position within the row
    let parity = n % 2;
    let m = 2 * ((p + parity) / 2) - parity;
    let signed = if m == 0 || j % 2 == 0 {
        m as i32
    } else {
        -(m as i32)
    };
    Ok((n as u32, signed))
}

/// Radial order n and signed m → Noll index j.
///
/// # Errors
/// [`ZernikeError::InvalidOrder`] unless `|m| ≤ n` and `n − |m|` is even.
pub fn nm_to_noll(n: u32, m: i32) -> Result<usize, ZernikeError> {
    let am = m.unsigned_abs();
    if am > n || (n - am) % 2 != 0 {
        return Err(ZernikeError::InvalidOrder { n, m });
    }
    let row = (n as usize) * (n as usize + 1) / 2;
    if am == 0 {
        return Ok(row + 1);
    }
    let j = row + am as usize;
    // Of the two candidates j and j + 1, cos takes the even one, sin the odd.
    let want_even = m > 0;
    Ok(if (j % 2 == 0) == want_even { j } else { j + 1 })
}

/// Number of terms with radial order ≤ `n_max`: `(n_max+1)(n_max+2)/2`.
pub fn terms_up_to_order(n_max: u32) -> usize {
    let n = n_max as usize;
    (n + 1) * (n + 2) / 2
}

/// The terms of a basis laid out by azimuthal order m, then k = (n − m)/2:
/// `cos[m][k]` and `sin[m][k]` are the coefficient indices (Noll j − 1) of the
/// cos/sin term, None beyond the basis' size; `norm[index]` its normalisation.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Layout {
    pub cos: Vec<Vec<Option<usize>>>,
    pub sin: Vec<Vec<Option<usize>>>,
    pub norm: Vec<f64>,
}

impl Layout {
    pub fn new(n_terms: usize) -> Self {
        let mut n_max = 0u32;
        while terms_up_to_order(n_max) < n_terms {
            n_max += 1;
        }
        let mut cos = Vec::new();
        let mut sin = Vec::new();
        for m in 0..=n_max {
            let kmax = ((n_max - m) / 2) as usize;
            cos.push(vec![None; kmax + 1]);
            sin.push(vec![None; kmax + 1]);
        }
        let mut norm = vec![0.0; n_terms];
        for (idx, nrm) in norm.iter_mut().enumerate() {
            let (n, m) = noll_to_nm(idx + 1).expect("j ≥ 1");
            let am = m.unsigned_abs();
            let k = ((n - am) / 2) as usize;
            let table = if m < 0 { &mut sin } else { &mut cos };
            table[am as usize][k] = Some(idx);
            *nrm = if m == 0 {
                f64::from(n + 1).sqrt()
            } else {
                (2.0 * f64::from(n + 1)).sqrt()
            };
        }
        Layout { cos, sin, norm }
    }

    /// Calls `visit(index, value, d/dX, d/dY)` for every term at the
    /// normalised point (X, Y), derivatives per unit of normalised coordinate.
    #[inline]
    pub fn for_each(&self, x: f64, y: f64, mut visit: impl FnMut(usize, f64, f64, f64)) {
        let t = x * x + y * y;
        let arg = 1.0 - 2.0 * t;
        // (X + iY)^m and (X + iY)^(m−1), updated as m grows.
        let (mut re, mut im) = (1.0, 0.0);
        let (mut re1, mut im1) = (0.0, 0.0);
        for m in 0..self.cos.len() {
            let fm = m as f64;
            let alpha = fm;
            let (mut p_prev, mut dp_prev) = (0.0, 0.0);
            let (mut p, mut dp) = (1.0, 0.0);
            for k in 0..self.cos[m].len() {
                if k == 1 {
                    p_prev = p;
                    dp_prev = dp;
                    p = (alpha + 1.0) + (alpha + 2.0) * (arg - 1.0) / 2.0;
                    dp = (alpha + 2.0) / 2.0;
                } else if k >= 2 {
                    let kf = k as f64;
                    let a = 2.0 * kf * (kf + alpha) * (2.0 * kf + alpha - 2.0);
                    let b = 2.0 * kf + alpha - 1.0;
                    let c = (2.0 * kf + alpha) * (2.0 * kf + alpha - 2.0);
                    let d = 2.0 * (kf + alpha - 1.0) * (kf - 1.0) * (2.0 * kf + alpha);
                    let p_next = (b * (c * arg + alpha * alpha) * p - d * p_prev) / a;
                    let dp_next =
                        (b * (c * arg + alpha * alpha) * dp + b * c * p - d * dp_prev) / a;
                    p_prev = p;
                    dp_prev = dp;
                    p = p_next;
                    dp = dp_next;
                }
                // Q = (−1)^k P(1 − 2t), dQ/dt = (−1)^k (−2) P'.
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                let q = sign * p;
                let dq = -2.0 * sign * dp;
                if let Some(idx) = self.cos[m][k] {
                    let nrm = self.norm[idx];
                    let v = q * re;
                    let dx = 2.0 * x * dq * re + fm * q * re1;
                    let dy = 2.0 * y * dq * re - fm * q * im1;
                    visit(idx, nrm * v, nrm * dx, nrm * dy);
                }
                if let Some(idx) = self.sin[m][k] {
                    let nrm = self.norm[idx];
                    let v = q * im;
                    let dx = 2.0 * x * dq * im + fm * q * im1;
                    let dy = 2.0 * y * dq * im + fm * q * re1;
                    visit(idx, nrm * v, nrm * dx, nrm * dy);
                }
            }
            // Advance to m + 1.
            re1 = re;
            im1 = im;
            let (nr, ni) = (re * x - im * y, re * y + im * x);
            re = nr;
            im = ni;
        }
    }
}
