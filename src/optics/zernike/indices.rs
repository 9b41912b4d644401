//! Noll index <-> (n, m) conversion.
//!
//! Within radial order n the Noll indices run from `n(n+1)/2 + 1` to
//! `(n+1)(n+2)/2` with |m| non-decreasing; for m != 0 the even j of the pair
//! is the cosine term (m > 0) and the odd j the sine term (m < 0).

use super::ZernikeError;

/// Number of Noll terms of radial order at most `n_max`: `(n_max+1)(n_max+2)/2`
/// (saturating at `usize::MAX`).
///
/// `terms_up_to_order(4) == 15`, `terms_up_to_order(20) == 231`.
pub fn terms_up_to_order(n_max: u32) -> usize {
    let n = u128::from(n_max);
    usize::try_from((n + 1) * (n + 2) / 2).unwrap_or(usize::MAX)
}

/// Radial order n and signed azimuthal order m of Noll index `j`.
///
/// `m > 0` is a `cos(m theta)` term, `m < 0` a `sin(|m| theta)` term, `m == 0`
/// rotationally symmetric. Examples: j = 1 -> (0, 0), 2 -> (1, 1),
/// 3 -> (1, -1), 4 -> (2, 0), 5 -> (2, -2), 6 -> (2, 2), 11 -> (4, 0).
///
/// # Errors
/// [`ZernikeError::InvalidIndex`] for `j == 0` or a `j` whose order does not
/// fit an `i32`.
pub fn noll_to_nm(j: usize) -> Result<(u32, i32), ZernikeError> {
    if j == 0 {
        return Err(ZernikeError::InvalidIndex { j });
    }
    let n = order_of(j);
    if n > i32::MAX as u64 {
        return Err(ZernikeError::InvalidIndex { j });
    }
    Ok(nm_of(j, n))
}

/// Noll index of the term with radial order `n` and signed azimuthal order `m`
/// (the inverse of [`noll_to_nm`]).
///
/// # Errors
/// [`ZernikeError::InvalidOrder`] unless `|m| <= n`, `n - |m|` is even and
/// `n <= i32::MAX`.
pub fn nm_to_noll(n: u32, m: i32) -> Result<usize, ZernikeError> {
    let am = m.unsigned_abs();
    if am > n || (n - am) % 2 != 0 || n > i32::MAX as u32 {
        return Err(ZernikeError::InvalidOrder { n, m });
    }
    usize::try_from(noll_of(u64::from(n), m)).map_err(|_| ZernikeError::InvalidOrder { n, m })
}

/// Radial order n of Noll index `j >= 1`: the n with
/// `n(n+1)/2 < j <= (n+1)(n+2)/2`.
pub(super) fn order_of(j: usize) -> u64 {
    let j = j as u128;
    // Float estimate, then exact integer correction (f64 loses digits for
    // very large j).
    let mut n = (((8.0 * j as f64 - 7.0).sqrt() - 1.0) / 2.0).max(0.0) as u128;
    while n > 0 && n * (n + 1) / 2 >= j {
        n -= 1;
    }
    while (n + 1) * (n + 2) / 2 < j {
        n += 1;
    }
    n as u64
}

/// (n, m) of `j >= 1` whose order `n` (from [`order_of`]) fits an `i32`.
fn nm_of(j: usize, n: u64) -> (u32, i32) {
    let p = j as u64 - n * (n + 1) / 2 - 1; // 0-based position within the order
    let am = n % 2 + 2 * ((p + (n + 1) % 2) / 2);
    let m = am as i32;
    let n = n as u32;
    if am == 0 {
        (n, 0)
    } else if j % 2 == 0 {
        (n, m)
    } else {
        (n, -m)
    }
}

/// Noll index of a valid (n, m), as u64 (no overflow for n <= i32::MAX).
pub(super) fn noll_of(n: u64, m: i32) -> u64 {
    let base = n * (n + 1) / 2 + 1; // first j of order n
    let am = u64::from(m.unsigned_abs());
    if am == 0 {
        return base;
    }
    // The pair with this |m| sits at positions |m| - 1 and |m|; pick the one
    // whose parity matches (even j: cosine, m > 0).
    let first = base + am - 1;
    let want_even = m > 0;
    if (first % 2 == 0) == want_even {
        first
    } else {
        first + 1
    }
}
