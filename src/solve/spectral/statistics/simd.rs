//! The hot loops of the statistics with their CPU dispatch: AVX2 and FMA
//! where the CPU has them (checked once at run time), portable code
//! elsewhere, the same results to rounding. The ingest's accumulation, the
//! lift of data-node sums onto the product nodes, the rows of weighted dot
//! products, and a cache prefetch hint.

use super::sums::NX;
use super::C64;
use crate::kernels::madd;

/// Whether this CPU has AVX2 and FMA (checked once).
pub(super) fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *HAS.get_or_init(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `z += Σ y · w[o..o + z.len()]` over `items = (y, o)`: the hot loop of the
/// ingest, four rows at a time so that z is loaded and stored once per four.
#[inline(always)]
fn accumulate_portable(z: &mut [f64], items: &[(f64, usize)], w: &[f64]) {
    let n = z.len();
    let mut quads = items.chunks_exact(4);
    for c in &mut quads {
        let w0 = &w[c[0].1..c[0].1 + n];
        let w1 = &w[c[1].1..c[1].1 + n];
        let w2 = &w[c[2].1..c[2].1 + n];
        let w3 = &w[c[3].1..c[3].1 + n];
        let (y0, y1, y2, y3) = (c[0].0, c[1].0, c[2].0, c[3].0);
        for k in 0..n {
            z[k] += y0 * w0[k] + y1 * w1[k] + y2 * w2[k] + y3 * w3[k];
        }
    }
    for &(y, o) in quads.remainder() {
        for (zk, wk) in z.iter_mut().zip(&w[o..o + n]) {
            *zk += y * wk;
        }
    }
}

/// [`accumulate_portable`] compiled for AVX2 and FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA ([`has_avx2_fma`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accumulate_avx2(z: &mut [f64], items: &[(f64, usize)], w: &[f64]) {
    accumulate_portable(z, items, w);
}

pub(super) fn accumulate(z: &mut [f64], items: &[(f64, usize)], w: &[f64], avx2: bool) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is true only where the CPU has AVX2 and FMA.
        unsafe { accumulate_avx2(z, items, w) };
        return;
    }
    let _ = avx2;
    accumulate_portable(z, items, w);
}

/// Asks the CPU to bring the cache lines of `v` into cache (a hint: no
/// effect on results, none at all off x86-64).
pub fn prefetch_lines<T>(v: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let bytes = std::mem::size_of_val(v);
        let base = v.as_ptr().cast::<i8>();
        for off in (0..bytes).step_by(64) {
            // SAFETY: a prefetch reads nothing architecturally and cannot
            // fault; the address lies within `v`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(base.add(off)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = v;
}

/// `Z' = Lᵀ Z`, row by row: Z lifted from the data nodes onto the product
/// nodes (real and imaginary parts apart).
pub(super) fn lift(z: &[C64], l: &[f64], re: &mut [f64], im: &mut [f64]) {
    /// Columns `c0..c0 + W` over every row, their sums in registers (one
    /// load per two multiply–adds, not five), each taken over the rows in
    /// order. Not fused: with `mul_add` the compiler left these scalar.
    #[inline(always)]
    fn columns<const W: usize>(z: &[C64], l: &[f64], c0: usize, re: &mut [f64], im: &mut [f64]) {
        let qg = re.len();
        let mut ar = [0.0f64; W];
        let mut ai = [0.0f64; W];
        for (z, row) in z.iter().zip(l.chunks_exact(qg)) {
            let lw: &[f64; W] = row[c0..c0 + W].try_into().expect("W columns");
            for t in 0..W {
                ar[t] += z.re * lw[t];
                ai[t] += z.im * lw[t];
            }
        }
        for t in 0..W {
            re[c0 + t] += ar[t];
            im[c0 + t] += ai[t];
        }
    }
    #[inline(always)]
    fn body(z: &[C64], l: &[f64], re: &mut [f64], im: &mut [f64]) {
        let qg = re.len();
        let mut c0 = 0;
        while c0 + 16 <= qg {
            columns::<16>(z, l, c0, re, im);
            c0 += 16;
        }
        while c0 + 4 <= qg {
            columns::<4>(z, l, c0, re, im);
            c0 += 4;
        }
        while c0 < qg {
            columns::<1>(z, l, c0, re, im);
            c0 += 1;
        }
    }
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn body_avx2(z: &[C64], l: &[f64], re: &mut [f64], im: &mut [f64]) {
        body(z, l, re, im);
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time).
        unsafe { body_avx2(z, l, re, im) };
        return;
    }
    body(z, l, re, im);
}

/// `Σ_j wr_j c^re_{y,j} + sign · wi_j c^im_{y,j}` for the `n` columns
/// `y = y0 … y0 + n − 1` of `cre`/`cim` (rows of length `q`), in one pass
/// over the nodes, four at a time with `n` accumulators in registers;
/// multiply–adds fused where `FMA`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn row_dots<const FMA: bool>(
    n: usize,
    wr: &[f64],
    wi: &[f64],
    sign: f64,
    cre: &[f64],
    cim: &[f64],
    q: usize,
    y0: usize,
) -> [f64; NX] {
    #[inline(always)]
    fn fixed<const N: usize, const FMA: bool>(
        wr: &[f64],
        wi: &[f64],
        sign: f64,
        cre: &[f64],
        cim: &[f64],
        q: usize,
        y0: usize,
    ) -> [f64; NX] {
        let rows = (y0 + N) * q;
        assert!(wr.len() >= q && wi.len() >= q && cre.len() >= rows && cim.len() >= rows);
        // Four values from `v` at `o`.
        #[inline(always)]
        fn four(v: &[f64], o: usize) -> [f64; 4] {
            debug_assert!(o + 4 <= v.len());
            // SAFETY: every call below has o + 4 ≤ v.len(): the weights
            // at j + 4 ≤ quads ≤ q ≤ wr.len(), wi.len(), the columns at
            // (y0 + t) q + j + 4 ≤ (y0 + N) q ≤ cre.len(), cim.len() (both
            // asserted above). Unchecked: the checks and their index
            // arithmetic were a quarter of the products' time.
            unsafe { v.as_ptr().add(o).cast::<[f64; 4]>().read_unaligned() }
        }
        let mut acc = [[0.0f64; 4]; N];
        let quads = q - q % 4;
        let mut j = 0;
        while j < quads {
            let a = four(wr, j);
            let b = four(wi, j);
            let sb = [sign * b[0], sign * b[1], sign * b[2], sign * b[3]];
            for (t, acc) in acc.iter_mut().enumerate() {
                let o = (y0 + t) * q + j;
                let c = four(cre, o);
                let d = four(cim, o);
                for l in 0..4 {
                    acc[l] = madd::<FMA>(sb[l], d[l], madd::<FMA>(a[l], c[l], acc[l]));
                }
            }
            j += 4;
        }
        let mut out = [0.0; NX];
        for (t, acc) in acc.iter().enumerate() {
            let o = (y0 + t) * q;
            let mut tail = 0.0;
            for j in quads..q {
                tail += wr[j] * cre[o + j] + sign * (wi[j] * cim[o + j]);
            }
            out[t] = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
        }
        out
    }
    match n {
        1 => fixed::<1, FMA>(wr, wi, sign, cre, cim, q, y0),
        2 => fixed::<2, FMA>(wr, wi, sign, cre, cim, q, y0),
        3 => fixed::<3, FMA>(wr, wi, sign, cre, cim, q, y0),
        4 => fixed::<4, FMA>(wr, wi, sign, cre, cim, q, y0),
        5 => fixed::<5, FMA>(wr, wi, sign, cre, cim, q, y0),
        6 => fixed::<6, FMA>(wr, wi, sign, cre, cim, q, y0),
        7 => fixed::<7, FMA>(wr, wi, sign, cre, cim, q, y0),
        _ => fixed::<8, FMA>(wr, wi, sign, cre, cim, q, y0),
    }
}
