//! A branch-free cosine of an argument given in cycles, for the renderer's
//! inner loop (`std` cos costs ~15 ns; this is a short polynomial that the
//! compiler vectorises).

/// `1.5 · 2^52`: adding and subtracting it rounds an f64 of magnitude
/// < 2^51 to the nearest integer under round-to-nearest-even.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

/// Taylor coefficients of cos(2π r) in r², through (2πr)^20: on |r| ≤ 1/2
/// (|2πr| ≤ π) the first omitted term bounds the error, π^22/22! = 7.3e-11.
const C: [f64; 11] = {
    let mut c = [0.0; 11];
    let w2 = 4.0 * std::f64::consts::PI * std::f64::consts::PI;
    let mut k = 0;
    let mut term = 1.0;
    while k < 11 {
        c[k] = term;
        // next: term · (−w²) / ((2k+1)(2k+2))
        term = -term * w2 / (((2 * k + 1) * (2 * k + 2)) as f64);
        k += 1;
    }
    c
};

/// `cos(2π x)` for `|x| < 2^51`, absolute error < 1e-10.
#[inline(always)]
pub fn cos_cycles(x: f64) -> f64 {
    let r = x - ((x + ROUND_MAGIC) - ROUND_MAGIC); // r ∈ [−0.5, 0.5]
    let y = r * r;
    let mut p = C[10];
    let mut k = 10;
    while k > 0 {
        k -= 1;
        p = p * y + C[k];
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_std_cos() {
        // Bound: truncation 7.3e-11 plus rounding of the reduced argument
        // (|x| ≤ 300 cycles leaves ~6e-14 cycles of error, 4e-13 rad).
        let mut worst: f64 = 0.0;
        for k in 0..2_000_000 {
            let x = -300.0 + k as f64 * 3.0e-4 + 1.234e-7;
            let err = (cos_cycles(x) - (std::f64::consts::TAU * x).cos()).abs();
            worst = worst.max(err);
        }
        assert!(worst < 1e-10, "worst error {worst:e}");
    }
}
