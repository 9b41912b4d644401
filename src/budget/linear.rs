//! The reconstruction's linearisation at its solution: the sensitivities of
//! its coefficients to the station's degrees of freedom, the noise
//! covariance split by surface, the station-induced covariance.
//!
//! The sensitivities come from the reconstruction's linearisation at its
//! solution: the weighted least-squares fit stops where `JᵀW r(c, θ) = 0`
//! (`J = ∂uv/∂c`, `r` the screen residuals, `θ` the station the fit
//! assumes), so a change `δθ` of the assumed station moves the
//! coefficients by `δc = −A⁻¹ B δθ`, `A = JᵀWJ`, `B = JᵀWX`,
//! `X = ∂uv/∂θ` (the measured screen points held fixed; the term
//! `(∂J/∂θ)ᵀ W r`, linear in the residuals, is left out as Gauss–Newton
//! leaves it out of `A`). `J` and `X` come from one dual trace per path
//! ([`super::station_dual`]), whitened by the same covariance the solve
//! used (smoothed as `reconstruct` smooths it, its outliers left out).
//! [`crate::solve::surfaces::station_error::station_induced_columns`]
//! (re-solves) stays as the independent check.

use std::collections::HashSet;

use crate::kernels::ordered::{chunk_sum, SUM_CHUNK};
use nalgebra::{DMatrix, DVector};

use super::station_dual::{StationDual, DOFS, WIDTH};
use super::DofEntry;
use crate::optics::station::{Station, StationUncertainty};
use crate::optics::trace::Plate;
use crate::solve::surfaces::path::LOCAL;
use crate::solve::surfaces::problem::{fill_row, whitener, BasisAt, Layout};
use crate::solve::surfaces::station_error::{from_columns, Columns, StationInduced};
use crate::solve::surfaces::{
    Observation, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
};

/// `S Σ Sᵀ` with `S` the per-σ contributions (n × m) and `Σ` the correlation.
pub fn station_covariance(
    dofs: &[DofEntry],
    correlation: &DMatrix<f64>,
    n: usize,
    per_unit: impl Fn(&DofEntry) -> &Vec<f64>,
) -> DMatrix<f64> {
    let s = DMatrix::from_fn(n, dofs.len(), |i, k| {
        per_unit(&dofs[k]).get(i).copied().unwrap_or(0.0) * dofs[k].std
    });
    &s * correlation * s.transpose()
}

/// The solution's noise covariance split into front (`nf` square) and back
/// (`nb` square) in coefficient order, zero rows for fixed coefficients.
pub fn noise_covariances(
    solution: &SurfaceSolution,
    nf: usize,
    nb: usize,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let layout = &solution.layout;
    let c = &solution.covariance;
    let pick = |n: usize, col: &dyn Fn(usize) -> Option<usize>| {
        DMatrix::from_fn(n, n, |i, j| match (col(i), col(j)) {
            (Some(a), Some(b)) if a < c.nrows() && b < c.ncols() => c[(a, b)],
            _ => 0.0,
        })
    };
    (
        pick(nf, &|k| layout.front_col(k)),
        pick(nb, &|k| layout.back_col(k)),
    )
}

/// The reconstruction's normal equations at its solution, over the
/// surfaces' free coefficients (`p`, in `layout`'s column order, nm) and
/// every degree of freedom (`Dof::ALL` order, per its unit), whitened;
/// and the information on the degrees of freedom with the coefficients
/// profiled out, computed without the normal equations' cancellation.
#[derive(Debug, Clone)]
pub struct Linearisation {
    /// The solution's unknowns.
    pub layout: Layout,
    /// `A = JᵀWJ`, p × p.
    pub a: DMatrix<f64>,
    /// `B = JᵀWX`, p × 28.
    pub b: DMatrix<f64>,
    /// `C = XᵀWX`, 28 × 28.
    pub c: DMatrix<f64>,
    /// `JᵀW r`, the residuals' gradient over the coefficients (≈ 0 at a
    /// converged solution).
    pub jr: DVector<f64>,
    /// `C − BᵀA⁻¹B`, 28 × 28, from a second pass: with `S = A⁻¹B` and
    /// `X⊥ = X − JS` row by row, `G − HᵀA⁻¹H`, `G = X⊥ᵀWX⊥`,
    /// `H = JᵀWX⊥` (an identity for any `S`, so `S`'s rounding cancels;
    /// what is left is the rounding of `X⊥`, not of `C`).
    pub schur: DMatrix<f64>,
    /// `Xᵀr − BᵀA⁻¹Jᵀr` the same way: `X⊥ᵀr − HᵀA⁻¹Jᵀr`.
    pub reduced_gradient: DVector<f64>,
    /// The rounding floor of `schur` along any direction `u` of the
    /// degrees of freedom, `Σ u_i² floor_ii`: `floor = 64 ε cond(A) G + (64 ε)²
    /// cond(A) C` (the solve against `A` loses `ε cond(A)` of `HᵀA⁻¹H ≤ G`;
    /// forming `X⊥` loses `ε` of `X`, squared in `G`, amplified by `A`).
    pub schur_floor: DMatrix<f64>,
    /// The solution's factor on `A⁻¹` (its covariance is `scale · A⁻¹`):
    /// the noise's information is `· / scale`.
    pub covariance_scale: f64,
    /// Residual components that entered.
    pub n_resid: usize,
    /// Measured paths the dual trace could not follow (front, back).
    pub failed: [usize; 2],
}

/// Accumulates [`Linearisation`] of `solution` (solved from `obs` on
/// `station`, world frame) on all cores: one dual trace per measured path
/// (two passes), its rows whitened by the pixel's covariance (smoothed by
/// `opts.covariance_smoothing_px` as the solve smoothed it), the pixels
/// the solve rejected left out.
///
/// # Errors
/// [`SurfaceError::IllConditioned`] when `A` is not positive definite.
pub fn linearise(
    obs: &Observations,
    station: &Station,
    solution: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<Linearisation, SurfaceError> {
    let weighted = opts.weighted(obs);
    let obs = &*weighted;
    let rejected: HashSet<[u32; 2]> = solution.rejected.iter().copied().collect();
    let pixels: Vec<Observation> = obs
        .pixels
        .iter()
        .filter(|p| !rejected.contains(&p.pixel))
        .copied()
        .collect();
    let layout = solution.layout;
    let plate = Plate::new(
        &station.element_frame(),
        solution.front.clone(),
        solution.back.clone(),
        opts.edge_margin_mm,
    );
    let rows = Rows {
        sd: StationDual::new(station),
        plate,
        layout,
    };
    let p = layout.columns();
    // The whitened residual rides along as the last column.
    let n = p + DOFS + 1;
    // Every parallel sum here is collected in chunk order and added in it:
    // the same inputs give the same budget bit for bit.
    let (gram, n_resid, failed) = chunk_sum(
        &pixels,
        SUM_CHUNK,
        (DMatrix::zeros(n, n), 0, [0; 2]),
        |chunk| rows.gram(chunk),
        |(g, r, f), (h, s, e)| (g + h, r + s, [f[0] + e[0], f[1] + e[1]]),
    );
    let a = gram.view((0, 0), (p, p)).into_owned();
    let b = gram.view((0, p), (p, DOFS)).into_owned();
    let c = gram.view((p, p), (DOFS, DOFS)).into_owned();
    let jr = gram.view((0, n - 1), (p, 1)).column(0).into_owned();
    let chol = a.clone().cholesky().ok_or(SurfaceError::IllConditioned {
        stage: "budget linearisation",
        condition_number: f64::INFINITY,
    })?;
    let s = chol.solve(&b);
    let (g, h, xr) = chunk_sum(
        &pixels,
        SUM_CHUNK,
        (
            DMatrix::zeros(DOFS, DOFS),
            DMatrix::zeros(p, DOFS),
            DVector::zeros(DOFS),
        ),
        |chunk| rows.projected(chunk, &s),
        |(g, h, x), (g2, h2, x2)| (g + g2, h + h2, x + x2),
    );
    let ah = chol.solve(&h);
    let schur = &g - h.transpose() * &ah;
    let schur = (&schur + schur.transpose()) * 0.5;
    let reduced_gradient = xr - ah.transpose() * &jr;
    let eig = a.clone().symmetric_eigen().eigenvalues;
    let cond = eig.max() / eig.min().max(f64::MIN_POSITIVE);
    let e = 64.0 * f64::EPSILON;
    let schur_floor = &g * (e * cond) + &c * (e * e * cond);
    Ok(Linearisation {
        layout,
        a,
        b,
        c,
        jr,
        schur,
        reduced_gradient,
        schur_floor,
        covariance_scale: solution.covariance_scale,
        n_resid,
        failed,
    })
}

/// What one pass over the pixels needs: the station in duals, the plate
/// at the solution, the unknowns.
struct Rows {
    sd: StationDual,
    plate: Plate,
    layout: Layout,
}

impl Rows {
    /// Calls `f` with each pixel's whitened rows `[J X r]` (its `m`
    /// residual components); returns the failed paths.
    #[allow(clippy::needless_range_loop)]
    fn each(&self, chunk: &[Observation], mut f: impl FnMut(&[Vec<f64>])) -> [usize; 2] {
        let (layout, plate) = (&self.layout, &self.plate);
        let p = layout.columns();
        let n = p + DOFS + 1;
        let mut at = [
            BasisAt::new(layout.front_terms),
            BasisAt::new(layout.back_terms),
            BasisAt::new(layout.front_terms),
        ];
        let mut failed = [0; 2];
        let mut rows = vec![vec![0.0; n]; 4];
        for ob in chunk {
            let mut idx = [0; 4];
            let mut m = 0;
            for k in 0..2 {
                if !ob.has(k) || !(if k == 0 { layout.use_s1 } else { layout.use_s2 }) {
                    continue;
                }
                let Ok(path) = self.sd.path(plate, ob.pixel, k) else {
                    failed[k] += 1;
                    continue;
                };
                at[0].eval(plate.front.basis(), path.hits[0]);
                if k == 1 {
                    at[1].eval(plate.back.basis(), path.hits[1]);
                    at[2].eval(plate.front.basis(), path.hits[2]);
                }
                for c in 0..2 {
                    idx[m] = 2 * k + c;
                    let row = &mut rows[m];
                    fill_row(
                        &mut row[..p],
                        &path,
                        c,
                        k == 1,
                        layout,
                        [&at[0], &at[1], &at[2]],
                    );
                    row[p..n - 1].copy_from_slice(&path.uv[c].g[LOCAL..WIDTH]);
                    row[n - 1] = path.uv[c].v - ob.s[k][c];
                    m += 1;
                }
            }
            if m == 0 {
                continue;
            }
            let l = whitener(ob, &idx[..m]);
            let mut x = [0.0; 4];
            for col in 0..n {
                for (xi, row) in x.iter_mut().zip(&rows[..m]) {
                    *xi = row[col];
                }
                l.forward_in_place(&mut x[..m]);
                for (xi, row) in x.iter().zip(&mut rows[..m]) {
                    row[col] = *xi;
                }
            }
            f(&rows[..m]);
        }
        failed
    }

    /// `[J X r]ᵀ[J X r]` of one chunk, its residual count and failed paths.
    fn gram(&self, chunk: &[Observation]) -> (DMatrix<f64>, usize, [usize; 2]) {
        let n = self.layout.columns() + DOFS + 1;
        let mut cols = DMatrix::<f64>::zeros(n, 4 * chunk.len());
        let mut r = 0;
        let failed = self.each(chunk, |rows| {
            for row in rows {
                cols.column_mut(r).copy_from_slice(row);
                r += 1;
            }
        });
        let gram = crate::kernels::gram::gram_of_columns(cols.as_slice(), n, r);
        (gram, r, failed)
    }

    /// With `X⊥ = X − J s` row by row: `X⊥ᵀX⊥`, `JᵀX⊥`, `X⊥ᵀr` of one chunk.
    fn projected(
        &self,
        chunk: &[Observation],
        s: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>, DVector<f64>) {
        let p = self.layout.columns();
        let mut g = DMatrix::zeros(DOFS, DOFS);
        let mut h = DMatrix::zeros(p, DOFS);
        let mut xr = DVector::zeros(DOFS);
        self.each(chunk, |rows| {
            for row in rows {
                let j = DVector::from_column_slice(&row[..p]);
                let x = DVector::from_column_slice(&row[p..p + DOFS]);
                let perp = x - s.tr_mul(&j);
                g.ger(1.0, &perp, &perp, 1.0);
                h.ger(1.0, &j, &perp, 1.0);
                xr.axpy(row[p + DOFS], &perp, 1.0);
            }
        });
        (g, h, xr)
    }
}

impl Linearisation {
    /// `−A⁻¹ B`: every free coefficient's change (nm, column order) per
    /// unit of every degree of freedom (`Dof::ALL` order).
    ///
    /// # Errors
    /// [`SurfaceError::IllConditioned`] when `A` is not positive definite.
    pub fn sensitivity(&self) -> Result<DMatrix<f64>, SurfaceError> {
        let chol = self
            .a
            .clone()
            .cholesky()
            .ok_or(SurfaceError::IllConditioned {
                stage: "budget linearisation",
                condition_number: f64::INFINITY,
            })?;
        Ok(-chol.solve(&self.b))
    }

    /// Column `dof` of `per_unit` (from [`Linearisation::sensitivity`]) in
    /// coefficient order: (front, back), Noll from j = 1, 0 where fixed;
    /// the back empty when `solution` did not reconstruct it.
    pub fn coefficients(
        &self,
        per_unit: &DMatrix<f64>,
        dof: usize,
        solution: &SurfaceSolution,
    ) -> (Vec<f64>, Vec<f64>) {
        let l = &self.layout;
        let nf = solution.front.coefficients_nm().len();
        let nb = if solution.back_fitted {
            solution.back.coefficients_nm().len()
        } else {
            0
        };
        let pick = |col: Option<usize>| col.map_or(0.0, |c| per_unit[(c, dof)]);
        (
            (0..nf).map(|k| pick(l.front_col(k))).collect(),
            (0..nb).map(|k| pick(l.back_col(k))).collect(),
        )
    }
}

/// [`crate::solve::surfaces::station_error::station_induced`] from the
/// linearisation: the same struct, each degree of freedom's column its
/// sensitivity times its σ.
///
/// # Errors
/// As [`super::assemble::budget`].
pub fn station_induced_linear(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    solution: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<StationInduced, SurfaceError> {
    let lin = linearise(obs, station, solution, opts)?;
    let per_unit = lin.sensitivity()?;
    let (nf, nb) = (
        solution.front.coefficients_nm().len(),
        solution.back.coefficients_nm().len(),
    );
    let columns: Columns = uncertainty
        .names
        .iter()
        .enumerate()
        .map(|(k, &dof)| {
            let sigma = uncertainty.covariance[(k, k)].sqrt();
            (sigma > 0.0).then(|| {
                let (f, b) = lin.coefficients(&per_unit, dof as usize, solution);
                let per_sigma = |v: &[f64], n: usize| -> Vec<f64> {
                    (0..n)
                        .map(|i| v.get(i).map_or(0.0, |x| x * sigma))
                        .collect()
                };
                (per_sigma(&f, nf), per_sigma(&b, nb))
            })
        })
        .collect();
    Ok(from_columns(&columns, uncertainty, nf, nb))
}
