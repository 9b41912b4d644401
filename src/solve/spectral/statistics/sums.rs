//! The inner products of one direction's columns over the product nodes —
//! of two columns, of the constant and of the data with each — from which
//! the normal equations are assembled ([`super::samples`]).

use super::samples::StatisticsSamples;
use super::simd::{has_avx2_fma, row_dots};
use crate::kernels::{exp_fast_with, madd, sincos_cycles_with};
use crate::solve::spectral::model::{Params, MAX_REFLECTIONS};

thread_local! {
    /// Per-thread work arrays of [`StatisticsSamples::dir_sums`].
    static SCRATCH: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Columns of one direction: `a_k` (B_k), `β_k` (μ_k), the κ column and the
/// model, at most 2K + 2.
pub(super) const NX: usize = 2 * MAX_REFLECTIONS + 2;

/// Inner products over one direction's samples: of two columns (`g`, upper
/// triangle), of the constant with a column (`e`), of the data with a column (`y`).
pub(super) struct DirSums {
    pub(super) g: [[f64; NX]; NX],
    pub(super) e: [f64; NX],
    pub(super) y: [f64; NX],
}

impl DirSums {
    pub(super) fn zero() -> Self {
        DirSums {
            g: [[0.0; NX]; NX],
            e: [0.0; NX],
            y: [0.0; NX],
        }
    }
}

/// The work arrays of [`StatisticsSamples::dir_sums_body`] over `q`
/// product nodes, carved from one scratch buffer: `e^{−κτ²}`, the model
/// column (re, im), the `nc` computed columns (re, im) and the same
/// weighted (re, im), each column's `q` values in a row.
struct Work<'s> {
    e: &'s mut [f64],
    mre: &'s mut [f64],
    mim: &'s mut [f64],
    cre: &'s mut [f64],
    cim: &'s mut [f64],
    pre: &'s mut [f64],
    pim: &'s mut [f64],
}

impl<'s> Work<'s> {
    /// Every array is written before it is read, but for the model (m),
    /// which is accumulated: only that one is zeroed, where it is used.
    #[inline(always)]
    fn carve(scratch: &'s mut Vec<f64>, q: usize, nc: usize) -> Self {
        if scratch.len() < (3 + 4 * nc) * q {
            scratch.resize((3 + 4 * nc) * q, 0.0);
        }
        let (e, rest) = scratch.split_at_mut(q);
        let (mre, rest) = rest.split_at_mut(q);
        let (mim, rest) = rest.split_at_mut(q);
        let (cre, rest) = rest.split_at_mut(nc * q);
        let (cim, rest) = rest.split_at_mut(nc * q);
        let (pre, rest) = rest.split_at_mut(nc * q);
        let pim = &mut rest[..nc * q];
        Work {
            e,
            mre,
            mim,
            cre,
            cim,
            pre,
            pim,
        }
    }
}

impl StatisticsSamples<'_> {
    /// The sums of direction `d` at `p` into `out` (written in place: they
    /// are 640 bytes, and returning them cost copies); only the entries the
    /// model's columns use are written, `y` zeroed without `data`.
    pub(super) fn dir_sums(
        &self,
        d: usize,
        p: &Params,
        derivs: bool,
        data: bool,
        out: &mut DirSums,
    ) {
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            if has_avx2_fma() {
                // SAFETY: the CPU has AVX2 and FMA (checked at run time).
                unsafe { self.dir_sums_avx2(d, p, derivs, data, &mut s, out) };
                return;
            }
            self.dir_sums_body::<false>(d, p, derivs, data, &mut s, out);
        })
    }

    /// [`Self::dir_sums_body`] compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA ([`has_avx2_fma`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn dir_sums_avx2(
        &self,
        d: usize,
        p: &Params,
        derivs: bool,
        data: bool,
        scratch: &mut Vec<f64>,
        out: &mut DirSums,
    ) {
        self.dir_sums_body::<true>(d, p, derivs, data, scratch, out);
    }

    /// The inner products of one direction, node-major passes over arrays
    /// (structure of arrays) that the compiler vectorises: the columns at
    /// every product node ([`Self::columns`]), then their weighted dot
    /// products. The model column `m = Σ B_k a_k` is last in the sums;
    /// being a combination of the `a_k`, its products are combined from
    /// theirs, not computed (a quarter to a third of the dot products).
    /// Multiply–adds are fused where `FMA` (the AVX2 and FMA build).
    #[inline(always)]
    pub(super) fn dir_sums_body<const FMA: bool>(
        &self,
        d: usize,
        p: &Params,
        derivs: bool,
        data: bool,
        scratch: &mut Vec<f64>,
        out: &mut DirSums,
    ) {
        let pd = &self.dirs[d];
        let k = p.k;
        let nx = if derivs { 2 * k + 2 } else { k + 1 };
        // Columns computed: all but the model's.
        let nc = nx - 1;
        let q = self.tables.dirs[d].gram.len();
        let w = Work::carve(scratch, q, nc);
        self.columns::<FMA>(
            d,
            p,
            derivs,
            w.e,
            (w.mre, w.mim),
            (&mut *w.cre, &mut *w.cim),
        );
        let (cre, cim) = (&*w.cre, &*w.cim);
        // Weighted columns: ½Re(M a b̄) + ½Re(D a b) = pr·b.re + pi·b.im with
        // pr + i·pi = ½M a + conj(½D a) (M real).
        let (pre, pim) = (w.pre, w.pim);
        for x in 0..nc {
            let r = x * q..(x + 1) * q;
            let it = pre[r.clone()]
                .iter_mut()
                .zip(pim[r.clone()].iter_mut())
                .zip(&cre[r.clone()])
                .zip(&cim[r])
                .zip(pd.hm.iter())
                .zip(pd.hd_re.iter().zip(pd.hd_im.iter()));
            for (((((pr, pi), &cr), &ci), &hm), (&hr, &hi)) in it {
                *pr = madd::<FMA>(hm + hr, cr, -hi * ci);
                *pi = madd::<FMA>(hm - hr, ci, -hi * cr);
            }
        }
        // One pass over the nodes per weight row: the constant's and the
        // data's against every column, each weighted column against the
        // columns from its own on (the upper triangle) — each row loaded
        // once per pass, not once per product.
        out.e = row_dots::<FMA>(nc, &pd.ez_re, &pd.ez_im, -1.0, cre, cim, q, 0);
        out.y = if data {
            row_dots::<FMA>(nc, &pd.zg_re, &pd.zg_im, -1.0, cre, cim, q, 0)
        } else {
            [0.0; NX]
        };
        for x in 0..nc {
            let (wr, wi) = (&pre[x * q..(x + 1) * q], &pim[x * q..(x + 1) * q]);
            let row = row_dots::<FMA>(nc - x, wr, wi, 1.0, cre, cim, q, x);
            out.g[x][x..nc].copy_from_slice(&row[..nc - x]);
        }
        model_products(out, p, nx);
    }

    /// The columns of direction `d` at `p` on the product nodes into
    /// `(cre, cim)`, one row of `q` per column, with `e = e^{−κτ²}` written
    /// first: `a_k = e^{−κτ²} e^{2πiδ_kτ}`; with derivatives also
    /// `β_k = 2πiτ B_k a_k` and the κ column `−τ² m`, the model
    /// `m = Σ B_k a_k` accumulated in `(mre, mim)`.
    #[inline(always)]
    fn columns<const FMA: bool>(
        &self,
        d: usize,
        p: &Params,
        derivs: bool,
        e: &mut [f64],
        (mre, mim): (&mut [f64], &mut [f64]),
        (cre, cim): (&mut [f64], &mut [f64]),
    ) {
        let pd = &self.dirs[d];
        let t = &self.tables.dirs[d];
        let ax = self.design.axes[d];
        let k = p.k;
        let q = t.gram.len();
        let tau = &t.gram.tau[..q];
        let kappa = p.kappa[self.design.falloff_group[d]];
        for (ej, &tj) in e.iter_mut().zip(tau) {
            *ej = exp_fast_with::<FMA>(-kappa * tj * tj);
        }
        for j in 0..k {
            let dl = ax.s(p.uv[j][0], p.uv[j][1]) - pd.mu_c;
            let (re, im) = (&mut cre[j * q..(j + 1) * q], &mut cim[j * q..(j + 1) * q]);
            for (((r, i), &ej), &tj) in re.iter_mut().zip(im.iter_mut()).zip(&*e).zip(tau) {
                let (c, s) = sincos_cycles_with::<FMA>(dl * tj);
                *r = ej * c;
                *i = ej * s;
            }
        }
        if !derivs {
            return;
        }
        // m = Σ B_k a_k, for the κ column.
        mre.fill(0.0);
        mim.fill(0.0);
        for j in 0..k {
            let b = p.amp[j];
            let (ar, ai) = (&cre[j * q..(j + 1) * q], &cim[j * q..(j + 1) * q]);
            for (((mr, mi), &r), &i) in mre.iter_mut().zip(mim.iter_mut()).zip(ar).zip(ai) {
                *mr = madd::<FMA>(b, r, *mr);
                *mi = madd::<FMA>(b, i, *mi);
            }
        }
        for j in 0..k {
            let f = std::f64::consts::TAU * p.amp[j];
            let (ar, br) = cre.split_at_mut(k * q);
            let (ai, bi) = cim.split_at_mut(k * q);
            let (ar, ai) = (&ar[j * q..(j + 1) * q], &ai[j * q..(j + 1) * q]);
            let (br, bi) = (&mut br[j * q..(j + 1) * q], &mut bi[j * q..(j + 1) * q]);
            for ((((r2, i2), &r), &i), &tj) in
                br.iter_mut().zip(bi.iter_mut()).zip(ar).zip(ai).zip(tau)
            {
                *r2 = -i * f * tj;
                *i2 = r * f * tj;
            }
        }
        let kr = &mut cre[2 * k * q..(2 * k + 1) * q];
        let ki = &mut cim[2 * k * q..(2 * k + 1) * q];
        for ((((r2, i2), &r), &i), &tj) in kr
            .iter_mut()
            .zip(ki.iter_mut())
            .zip(&*mre)
            .zip(&*mim)
            .zip(tau)
        {
            *r2 = -tj * tj * r;
            *i2 = -tj * tj * i;
        }
    }
}

/// The products of the model column `m = Σ B_j a_j` (the last of `nx`),
/// by linearity from those of the `a_j` already in `out`.
#[inline(always)]
fn model_products(out: &mut DirSums, p: &Params, nx: usize) {
    let k = p.k;
    let nc = nx - 1;
    let m = nx - 1;
    let g = |x: usize, y: usize| out.g[x.min(y)][x.max(y)];
    let mut gm = [0.0; NX];
    for (x, gmx) in gm.iter_mut().enumerate().take(nc) {
        *gmx = (0..k).map(|j| p.amp[j] * g(x, j)).sum();
    }
    let gmm: f64 = (0..k).map(|j| p.amp[j] * gm[j]).sum();
    for (x, &v) in gm.iter().enumerate().take(nc) {
        out.g[x][m] = v;
    }
    out.g[m][m] = gmm;
    out.e[m] = (0..k).map(|j| p.amp[j] * out.e[j]).sum();
    out.y[m] = (0..k).map(|j| p.amp[j] * out.y[j]).sum();
}
