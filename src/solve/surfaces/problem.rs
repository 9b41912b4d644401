//! The inverse problem's data and its normal equations: the measured screen
//! points of every pixel, which Zernike terms are free, and the weighted
//! Gauss–Newton system `JᵀJ δ = −Jᵀr` built from one dual trace per path.

use nalgebra::{DMatrix, DVector};

pub use super::observe::{Observation, Observations, Uncertainty};
use rayon::prelude::*;

use super::path::{back_path, front_path, DualPath, SLOT_BACK, SLOT_FRONT_IN, SLOT_FRONT_OUT};
use crate::kernels::SmallCholesky;
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::optics::zernike::ZernikeBasis;

/// Millimetres per nanometre: coefficients are nm, the tracer works in mm.
const MM_PER_NM: f64 = 1e-6;

/// Which coefficients are unknowns and which data enter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Terms of the front surface (Noll 1..=n).
    pub front_terms: usize,
    /// Terms of the back surface.
    pub back_terms: usize,
    /// Front coefficients j ≥ 2 are unknowns (piston is the reference plane's).
    pub fit_front: bool,
    /// Back coefficients are unknowns.
    pub fit_back: bool,
    /// The back's piston (its departure from the nominal thickness) is an unknown.
    pub back_piston: bool,
    /// S1 residuals enter.
    pub use_s1: bool,
    /// S2 residuals enter.
    pub use_s2: bool,
}

impl Layout {
    fn front_cols(&self) -> usize {
        if self.fit_front {
            self.front_terms - 1
        } else {
            0
        }
    }

    fn back_first(&self) -> usize {
        usize::from(!self.back_piston)
    }

    /// Number of unknowns.
    pub fn columns(&self) -> usize {
        self.front_cols()
            + if self.fit_back {
                self.back_terms - self.back_first()
            } else {
                0
            }
    }

    /// Column of front coefficient index `k` (Noll k + 1), if free.
    pub fn front_col(&self, k: usize) -> Option<usize> {
        (self.fit_front && k >= 1 && k < self.front_terms).then(|| k - 1)
    }

    /// Column of back coefficient index `k`, if free.
    pub fn back_col(&self, k: usize) -> Option<usize> {
        (self.fit_back && k >= self.back_first() && k < self.back_terms)
            .then(|| self.front_cols() + k - self.back_first())
    }
}

/// The Gauss–Newton system at one point.
#[derive(Debug, Clone)]
pub struct Normal {
    /// `JᵀJ` of the σ-weighted residuals (coefficients in nm).
    pub a: DMatrix<f64>,
    /// `Jᵀr`.
    pub b: DVector<f64>,
    /// `rᵀr` (χ² when σ is known).
    pub chi2: f64,
    /// Residual components that entered (two per path).
    pub n_resid: usize,
    /// Measured paths the model could not trace (front, back), e.g. a
    /// back reflection the current surfaces send through the rim.
    pub failed: [usize; 2],
}

impl Normal {
    fn zeros(p: usize) -> Self {
        Normal {
            a: DMatrix::zeros(p, p),
            b: DVector::zeros(p),
            chi2: 0.0,
            n_resid: 0,
            failed: [0; 2],
        }
    }

    fn merge(mut self, o: Normal) -> Self {
        self.a += o.a;
        self.b += o.b;
        self.chi2 += o.chi2;
        self.n_resid += o.n_resid;
        self.failed[0] += o.failed[0];
        self.failed[1] += o.failed[1];
        self
    }
}

/// Basis values and gradients at one point, per surface.
pub(crate) struct BasisAt {
    v: Vec<f64>,
    dx: Vec<f64>,
    dy: Vec<f64>,
}

impl BasisAt {
    pub(crate) fn new(n: usize) -> Self {
        BasisAt {
            v: vec![0.0; n],
            dx: vec![0.0; n],
            dy: vec![0.0; n],
        }
    }

    pub(crate) fn eval(&mut self, basis: &ZernikeBasis, xy: [f64; 2]) {
        // Lengths match by construction.
        let _ = basis.eval_into(xy[0], xy[1], &mut self.v, &mut self.dx, &mut self.dy);
    }
}

/// Adds slot `slot`'s contribution of path `p` (component `c`) to `row`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn add_slot<const N: usize>(
    row: &mut [f64],
    p: &DualPath<N>,
    c: usize,
    slot: usize,
    at: &BasisAt,
    col: impl Fn(usize) -> Option<usize>,
    inv_sigma: f64,
) {
    let g = &p.uv[c].g;
    let (gh, gx, gy) = (g[slot], g[slot + 1], g[slot + 2]);
    let k = MM_PER_NM * inv_sigma;
    for (t, ((v, dx), dy)) in at.v.iter().zip(&at.dx).zip(&at.dy).enumerate() {
        if let Some(col) = col(t) {
            row[col] += (gh * v + gx * dx + gy * dy) * k;
        }
    }
}

/// Builds the normal equations (and χ²) of `layout` at the surfaces of
/// `plate`, on all cores. With `jacobian` false only χ² is computed.
pub fn accumulate(
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    layout: &Layout,
    jacobian: bool,
) -> Normal {
    let p = if jacobian { layout.columns() } else { 0 };
    // The chunks' sums are added in chunk order, not in the order rayon's
    // work stealing happens to join them: floating-point addition does not
    // associate, and the same inputs must give the same surfaces bit for bit.
    crate::kernels::ordered::chunk_sum(
        &obs.pixels,
        crate::kernels::ordered::SUM_CHUNK,
        Normal::zeros(p),
        |chunk| accumulate_chunk(chunk, obs, station, plate, layout, p),
        Normal::merge,
    )
}

#[allow(clippy::needless_range_loop)]
fn accumulate_chunk(
    chunk: &[Observation],
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    layout: &Layout,
    p: usize,
) -> Normal {
    let mut out = Normal::zeros(p);
    // One column per residual (contiguous in column-major storage).
    let mut cols = DMatrix::<f64>::zeros(p, 4 * chunk.len());
    let mut res = DVector::<f64>::zeros(4 * chunk.len());
    let mut scratch = Scratch::new(layout, p);
    let mut r = 0;
    for ob in chunk {
        let m = scratch.pixel(ob, obs, station, plate, layout, p, &mut out.failed);
        if m == 0 {
            continue;
        }
        scratch.whiten(ob, m, p);
        for i in 0..m {
            res[r + i] = scratch.res[i];
            if p > 0 {
                cols.column_mut(r + i).copy_from_slice(&scratch.rows[i]);
            }
        }
        r += m;
    }
    let used = res.rows(0, r);
    out.chi2 = used.norm_squared();
    out.n_resid = r;
    if p > 0 && r > 0 {
        // JᵀJ as (Jᵀ)(Jᵀ)ᵀ through matrixmultiply's blocked kernel, the
        // transpose a view (`gemm_tr` would use dot products).
        out.a = crate::kernels::gram::gram_of_columns(cols.as_slice(), p, r);
        out.b.gemv(1.0, &cols.columns(0, r), &used, 0.0);
    }
    out
}

/// Each pixel's χ² (sum of its whitened squared residuals) at the surfaces
/// of `plate`; NaN where no measured path could be traced.
pub fn pixel_chi2(
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    layout: &Layout,
) -> Vec<f64> {
    obs.pixels
        .par_chunks(128)
        .flat_map_iter(|chunk| {
            let mut scratch = Scratch::new(layout, 0);
            let mut failed = [0; 2];
            chunk
                .iter()
                .map(|ob| {
                    let m = scratch.pixel(ob, obs, station, plate, layout, 0, &mut failed);
                    if m == 0 {
                        return f64::NAN;
                    }
                    scratch.whiten(ob, m, 0);
                    scratch.res[..m].iter().map(|r| r * r).sum()
                })
                .collect::<Vec<f64>>()
        })
        .collect()
}

/// The Cholesky factor `L` (`C = LLᵀ`) of the covariance of the residual
/// components `idx` of `ob` (0–1 S1's u, v; 2–3 S2's); by the standard
/// deviations alone where that block is not positive definite.
pub(crate) fn whitener(ob: &Observation, idx: &[usize]) -> SmallCholesky<4> {
    let m = idx.len();
    SmallCholesky::<4>::from_fn(m, |i, j| ob.cov[idx[i]][idx[j]]).unwrap_or_else(|| {
        let mut var = [0.0; 4];
        for (v, &a) in var.iter_mut().zip(idx) {
            *v = ob.cov[a][a];
        }
        SmallCholesky::diagonal(&var[..m])
    })
}

/// Per-pixel work space: basis values at the hits, raw rows and residuals.
struct Scratch {
    f_in: BasisAt,
    f_out: BasisAt,
    bk: BasisAt,
    rows: [Vec<f64>; 4],
    res: [f64; 4],
    idx: [usize; 4],
}

impl Scratch {
    /// Whitens the `m` residuals (and rows, when `p > 0`) with the
    /// covariance of the components present: `L⁻¹(·)`, `C = LLᵀ`; by the
    /// standard deviations alone where that block is not positive definite.
    fn whiten(&mut self, ob: &Observation, m: usize, p: usize) {
        let l = whitener(ob, &self.idx[..m]);
        l.forward_in_place(&mut self.res[..m]);
        let mut x = [0.0; 4];
        for c in 0..p {
            for (xi, row) in x.iter_mut().zip(&self.rows[..m]) {
                *xi = row[c];
            }
            l.forward_in_place(&mut x[..m]);
            for (xi, row) in x.iter().zip(&mut self.rows[..m]) {
                row[c] = *xi;
            }
        }
    }

    fn new(layout: &Layout, p: usize) -> Self {
        Scratch {
            f_in: BasisAt::new(layout.front_terms),
            f_out: BasisAt::new(layout.front_terms),
            bk: BasisAt::new(layout.back_terms),
            rows: std::array::from_fn(|_| vec![0.0; p]),
            res: [0.0; 4],
            idx: [0; 4],
        }
    }

    /// Traces the pixel's measured paths; fills unweighted residuals and
    /// rows for the `m` components present (returned), in `idx` order.
    #[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
    fn pixel(
        &mut self,
        ob: &Observation,
        obs: &Observations,
        station: &Station,
        plate: &Plate,
        layout: &Layout,
        p: usize,
        failed: &mut [usize; 2],
    ) -> usize {
        let mut m = 0;
        for k in 0..2 {
            if !ob.has(k) || !(if k == 0 { layout.use_s1 } else { layout.use_s2 }) {
                continue;
            }
            let traced = if k == 0 {
                front_path(plate, &obs.camera, &ob.dir, &station.screen)
            } else {
                back_path(plate, &obs.camera, &ob.dir, &station.screen)
            };
            let Ok(path) = traced else {
                failed[k] += 1;
                continue;
            };
            if p > 0 && layout.fit_front {
                self.f_in.eval(plate.front.basis(), path.hits[0]);
                if k == 1 {
                    self.f_out.eval(plate.front.basis(), path.hits[2]);
                }
            }
            if p > 0 && layout.fit_back && k == 1 {
                self.bk.eval(plate.back.basis(), path.hits[1]);
            }
            for c in 0..2 {
                self.idx[m] = 2 * k + c;
                self.res[m] = path.uv[c].v - ob.s[k][c];
                if p > 0 {
                    self.fill_row(m, &path, c, k == 1, layout);
                }
                m += 1;
            }
        }
        m
    }

    /// Row `m` of the Jacobian: component `c` of `path` (a back path when
    /// `back`) over the free coefficients, from the basis values at its hits.
    fn fill_row(&mut self, m: usize, path: &DualPath, c: usize, back: bool, layout: &Layout) {
        let at = [&self.f_in, &self.bk, &self.f_out];
        fill_row(&mut self.rows[m], path, c, back, layout, at);
    }
}

/// One row of the Jacobian over `layout`'s free coefficients: component
/// `c` of `path` (a back path when `back`), from the basis values at its
/// hits `at` (front entry, back, front exit).
pub(crate) fn fill_row<const N: usize>(
    row: &mut [f64],
    path: &DualPath<N>,
    c: usize,
    back: bool,
    layout: &Layout,
    at: [&BasisAt; 3],
) {
    row.iter_mut().for_each(|x| *x = 0.0);
    let front_col = |t| layout.front_col(t);
    if layout.fit_front {
        add_slot(row, path, c, SLOT_FRONT_IN, at[0], front_col, 1.0);
    }
    if back && layout.fit_back {
        add_slot(row, path, c, SLOT_BACK, at[1], |t| layout.back_col(t), 1.0);
    }
    if back && layout.fit_front {
        add_slot(row, path, c, SLOT_FRONT_OUT, at[2], front_col, 1.0);
    }
}

#[cfg(test)]
#[path = "problem_tests.rs"]
mod tests;
