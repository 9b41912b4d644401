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

/// Taylor coefficients of cos(w) in w² through w^16, and of sin(w)/w in w²
/// through w^16 (sin to w^17): on |w| ≤ π/4 the first omitted terms bound
/// the error, (π/4)^18/18! = 2e-18 and (π/4)^19/19! = 8e-20.
const COS_W: [f64; 9] = taylor(0);
const SIN_W: [f64; 9] = taylor(1);

const fn taylor(first: usize) -> [f64; 9] {
    let mut c = [0.0; 9];
    let mut term = 1.0;
    let mut n = 1;
    while n <= first {
        term /= n as f64;
        n += 1;
    }
    let mut k = 0;
    while k < 9 {
        c[k] = term;
        // next: term · (−1) / ((n)(n+1)) for the power two higher
        term = -term / ((n * (n + 1)) as f64);
        n += 2;
        k += 1;
    }
    c
}

/// `(cos 2πx, sin 2πx)` for `|x| < 2^50`, absolute error < 1e-15 plus the
/// rounding of the reduced argument (~ulp(x) cycles): x is reduced to the
/// nearest quarter cycle, |r| ≤ 1/8, and both series share it. Twice as
/// fast as two [`cos_cycles`] and more accurate.
#[inline(always)]
pub fn sincos_cycles(x: f64) -> (f64, f64) {
    sincos_cycles_with::<false>(x)
}

/// `a · b + c`, fused into one rounding where `FMA` (only for code compiled
/// with the `fma` target feature: elsewhere `mul_add` is a library call).
#[inline(always)]
pub fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// [`sincos_cycles`] with its polynomial's steps fused where `FMA` ([`madd`]).
#[inline(always)]
pub fn sincos_cycles_with<const FMA: bool>(x: f64) -> (f64, f64) {
    // Nearest quarter count q; with the magic number's exponent fixed, the
    // low bits of `b` are q's in two's complement (no branch, no float→int
    // conversion: the loop around stays vectorisable).
    let b = (4.0 * x + ROUND_MAGIC).to_bits();
    let q = f64::from_bits(b) - ROUND_MAGIC;
    let w = std::f64::consts::TAU * (x - 0.25 * q); // |w| ≤ π/4
    let w2 = w * w;
    let mut c = COS_W[8];
    let mut s = SIN_W[8];
    let mut k = 8;
    while k > 0 {
        k -= 1;
        c = madd::<FMA>(c, w2, COS_W[k]);
        s = madd::<FMA>(s, w2, SIN_W[k]);
    }
    s *= w;
    // 2πx = qπ/2 + w: rotate (cos w, sin w) by q quarter turns: an odd q
    // swaps them (one negated), q ≡ 2, 3 (mod 4) flips both signs.
    let odd = b & 1 == 1;
    let (c, s) = (if odd { -s } else { c }, if odd { c } else { s });
    let flip = (b & 2) << 62;
    (
        f64::from_bits(c.to_bits() ^ flip),
        f64::from_bits(s.to_bits() ^ flip),
    )
}

/// Taylor coefficients of e^r through r^13: on |r| ≤ ln 2 / 2 the first
/// omitted term bounds the relative error, 0.347^14/14! = 4e-18.
const EXP_C: [f64; 14] = {
    let mut c = [0.0; 14];
    let mut k = 0;
    let mut term = 1.0;
    while k < 14 {
        c[k] = term;
        term /= (k + 1) as f64;
        k += 1;
    }
    c
};

/// `e^x` for `|x| ≤ 700` (relative error ~2e-16; beyond, clamped there), with
/// neither branch nor table, so that loops of it vectorise: x = n ln 2 + r,
/// |r| ≤ ln 2 / 2, `2^n` built from the bits of the magic-rounded n.
#[inline(always)]
pub fn exp_fast(x: f64) -> f64 {
    exp_fast_with::<false>(x)
}

/// [`exp_fast`] with its polynomial's steps fused where `FMA` ([`madd`]).
#[inline(always)]
pub fn exp_fast_with<const FMA: bool>(x: f64) -> f64 {
    const LN2_HI: f64 = 0.693_147_180_369_123_8; // ln 2 to 33 bits: n · LN2_HI is exact
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    let x = x.clamp(-700.0, 700.0);
    let b = (x * std::f64::consts::LOG2_E + ROUND_MAGIC).to_bits();
    let n = f64::from_bits(b) - ROUND_MAGIC;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let mut p = EXP_C[13];
    let mut k = 13;
    while k > 0 {
        k -= 1;
        p = madd::<FMA>(p, r, EXP_C[k]);
    }
    // 2^n: n's two's complement sits in b's low bits (b − magic's bits).
    let n_bits = b.wrapping_sub(ROUND_MAGIC.to_bits());
    p * f64::from_bits(n_bits.wrapping_add(1023) << 52)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_fast_matches_std() {
        exp_within_bounds(exp_fast);
        // The fused steps: the same bounds (one rounding fewer per step).
        exp_within_bounds(exp_fast_with::<true>);
    }

    fn exp_within_bounds(exp_fast: fn(f64) -> f64) {
        // Relative error: the polynomial's 4e-18 plus the rounding of r
        // (|n| ≤ 1010 times LN2_LO's 1e-26 error, and a few ulps of the
        // Horner sum): 1e-15 is ~5 ulps.
        let mut worst: f64 = 0.0;
        for k in -69_900..=69_900 {
            let x = k as f64 * 0.01 + 0.003_7; // −699 … 699
            let (a, b) = (exp_fast(x), x.exp());
            worst = worst.max(((a - b) / b).abs());
        }
        assert!(worst < 1e-15, "{worst}");
        assert_eq!(exp_fast(0.0), 1.0);
        assert!(exp_fast(-1e6) > 0.0 && exp_fast(-1e6) < 1e-300);
    }

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

    #[test]
    fn sincos_matches_std() {
        sincos_within_bounds(sincos_cycles);
        // The fused steps: the same bounds (one rounding fewer per step).
        sincos_within_bounds(sincos_cycles_with::<true>);
    }

    fn sincos_within_bounds(sincos_cycles: fn(f64) -> (f64, f64)) {
        // Bound: series 2e-18; the reduced argument carries the rounding of
        // x (ulp(300) = 5.7e-14 cycles, 3.6e-13 rad) — and std's own
        // reduction of 2πx the same — so 1e-12 over |x| ≤ 300, and 1e-15
        // near zero where x is exact to 1e-17.
        let mut worst: f64 = 0.0;
        for k in 0..2_000_000 {
            let x = -300.0 + k as f64 * 3.0e-4 + 1.234e-7;
            let (c, s) = sincos_cycles(x);
            let w = std::f64::consts::TAU * x;
            worst = worst.max((c - w.cos()).abs()).max((s - w.sin()).abs());
        }
        assert!(worst < 1e-12, "worst error {worst:e}");
        let mut near: f64 = 0.0;
        for k in 0..100_000 {
            let x = -1.0 + k as f64 * 2.0e-5 + 1.234e-9;
            let (c, s) = sincos_cycles(x);
            let w = std::f64::consts::TAU * x;
            near = near.max((c - w.cos()).abs()).max((s - w.sin()).abs());
        }
        assert!(near < 1e-15, "worst error near zero {near:e}");
    }
}
