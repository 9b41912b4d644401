//! What the data pin down: the Fisher information of the station's degrees
//! of freedom in the element's own measurement, the surfaces estimated at
//! the same time, and the Gauss–Newton step that estimates chosen degrees
//! of freedom jointly with the surfaces.
//!
//! From the reconstruction's linearisation ([`Linearisation`]: `A = JᵀWJ`,
//! `B = JᵀWX`, `C = XᵀWX`, whitened by the σ the solve used, whose true
//! scale is the solution's `covariance_scale`), the information on the
//! degrees of freedom with the coefficients marginalised (profiled out) is
//!
//! `F = (C − Bᵀ A⁻¹ B) / scale`  (per unit²),
//!
//! the inverse of the θ-block of the joint normal equations' inverse. In σ
//! units of the prior (`y_i = δθ_i / σ_i`) it is `F̃ = S F S`, `S =
//! diag(σ)`, beside the prior's correlation `R`.
//!
//! [`Identifiability`] entries, exactly:
//! - one per degree of freedom with a σ, in the uncertainty's order:
//!   `data_std = 1/√F̃_ii`, the σ of that degree of freedom estimated with
//!   the surfaces while every other degree of freedom is held at its
//!   assumed value; `posterior_std = 1/√(1 + F̃_ii)`, the same with its
//!   prior (σ 1) added; `prior_std = 1`. `data_std` is `None` where
//!   `F̃_ii` is below the rounding floor (below), and the posterior is
//!   then the prior.
//! - then the eigen-combinations `w` of `F̃` (unit vectors in `y`) whose
//!   eigenvalue `λ < 1` (the data determine them worse than a unit prior
//!   would), worst first, at most [`WORST`]: `data_std = 1/√λ`, the σ of
//!   `wᵀy` with every listed degree of freedom and the surfaces estimated
//!   together; `None` where `λ` is below the rounding of `C − BᵀA⁻¹B`
//!   (degenerate: the data cannot tell that combination from a change of
//!   the surfaces); `prior_std = √(wᵀRw)`; `posterior_std` from
//!   `(R⁻¹ + F̃)⁻¹ = R (I + F̃ R)⁻¹` (the prior where degenerate).
//!
//! The rounding floor: [`Linearisation::schur`] is computed from the rows
//! projected off the surfaces (no cancellation of `C` against `BᵀA⁻¹B`,
//! which would lose `ε cond(A)` of `C`); an information below its floor
//! (`Σ u_i² floor_ii` along `u`, [`Linearisation::schur_floor`]) is
//! indistinguishable from none.
//!
//! Hand-written: a Schur complement and one symmetric eigen-decomposition
//! of nalgebra's.

use nalgebra::{DMatrix, DVector};

use super::linear::Linearisation;
use super::Identifiability;
use crate::optics::station::{Dof, StationUncertainty};
use crate::solve::surfaces::SurfaceError;

/// At most this many worst-determined combinations are listed.
pub const WORST: usize = 5;

fn ill(stage: &'static str) -> SurfaceError {
    SurfaceError::IllConditioned {
        stage,
        condition_number: f64::INFINITY,
    }
}

/// The marginal information `F` of the degrees of freedom `dofs` (their
/// order; every other one held at its assumed value), per unit², and its
/// rounding floor ([`Linearisation::schur_floor`], scaled alike).
pub fn marginal_information(lin: &Linearisation, dofs: &[Dof]) -> (DMatrix<f64>, DMatrix<f64>) {
    let m = dofs.len();
    let scale = lin.covariance_scale;
    let pick = |x: &DMatrix<f64>| {
        DMatrix::from_fn(m, m, |r, c| x[(dofs[r] as usize, dofs[c] as usize)] / scale)
    };
    (pick(&lin.schur), pick(&lin.schur_floor))
}

/// The Gauss–Newton step of the degrees of freedom `dofs` (per unit) with
/// the surfaces' coefficients eliminated, from the data alone:
/// `(C − BᵀA⁻¹B) δθ = −(Xᵀr − BᵀA⁻¹ Jᵀr)`, and its covariance `F⁻¹`.
/// Added to the assumed station, it is the joint least-squares estimate to
/// first order.
///
/// # Errors
/// [`SurfaceError::IllConditioned`] when `F` is singular (a degenerate
/// choice of degrees of freedom).
pub fn joint_step(
    lin: &Linearisation,
    dofs: &[Dof],
) -> Result<(DVector<f64>, DMatrix<f64>), SurfaceError> {
    let m = dofs.len();
    let g = DVector::from_fn(m, |r, _| lin.reduced_gradient[dofs[r] as usize]);
    let (f, _) = marginal_information(lin, dofs);
    let chol = f.cholesky().ok_or(ill("joint step"))?;
    let step = -chol.solve(&g) / lin.covariance_scale;
    Ok((step, chol.inverse()))
}

/// [`super::Budget::identifiability`] of the degrees of freedom with a σ
/// in `uncertainty` (definitions in the module doc).
///
/// # Errors
/// [`SurfaceError::IllConditioned`] when `A` is not positive definite.
pub fn identifiability(
    lin: &Linearisation,
    uncertainty: &StationUncertainty,
) -> Result<Vec<Identifiability>, SurfaceError> {
    let keep: Vec<usize> = (0..uncertainty.names.len())
        .filter(|&k| uncertainty.covariance[(k, k)] > 0.0)
        .collect();
    if keep.is_empty() {
        return Ok(Vec::new());
    }
    let dofs: Vec<Dof> = keep.iter().map(|&k| uncertainty.names[k]).collect();
    let sigma: Vec<f64> = keep
        .iter()
        .map(|&k| uncertainty.covariance[(k, k)].sqrt())
        .collect();
    let m = dofs.len();
    let (f, floor) = marginal_information(lin, &dofs);
    let ft = DMatrix::from_fn(m, m, |r, c| f[(r, c)] * sigma[r] * sigma[c]);
    let corr = DMatrix::from_fn(m, m, |r, c| {
        uncertainty.covariance[(keep[r], keep[c])] / (sigma[r] * sigma[c])
    });
    let mut out: Vec<Identifiability> = (0..m)
        .map(|i| {
            let fi = ft[(i, i)];
            let data_std = (fi > floor[(i, i)] * sigma[i] * sigma[i]).then(|| 1.0 / fi.sqrt());
            Identifiability {
                combination: vec![(dofs[i], 1.0)],
                prior_std: 1.0,
                data_std,
                posterior_std: data_std.map_or(1.0, |_| 1.0 / (1.0 + fi).sqrt()),
            }
        })
        .collect();
    if m < 2 {
        return Ok(out);
    }
    // (R⁻¹ + F̃)⁻¹ = R (I + F̃ R)⁻¹: no inverse of a possibly singular R.
    let post = (DMatrix::identity(m, m) + &ft * &corr)
        .lu()
        .solve(&corr.transpose())
        .map(|x| x.transpose())
        .ok_or(ill("identifiability"))?;
    let eig = ft.symmetric_eigen();
    let mut order: Vec<usize> = (0..m).filter(|&k| eig.eigenvalues[k] < 1.0).collect();
    order.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
    for &k in order.iter().take(WORST) {
        // The sign that makes the largest weight positive.
        let w = eig.eigenvectors.column(k);
        let big = w
            .iter()
            .fold(0.0_f64, |a, x| if x.abs() > a.abs() { *x } else { a });
        let w = w * big.signum();
        let w = &w;
        let lambda = eig.eigenvalues[k];
        let prior_std = (w.transpose() * &corr * w)[(0, 0)].max(0.0).sqrt();
        // The floor along the combination, in these units: Σ u_i² floor_ii,
        // u = S w (the columns' roundings are independent: they do not
        // cancel where the columns themselves do).
        let floor_w: f64 = (0..m)
            .map(|i| (w[i] * sigma[i]).powi(2) * floor[(i, i)])
            .sum();
        let data_std = (lambda > floor_w).then(|| 1.0 / lambda.sqrt());
        out.push(Identifiability {
            combination: dofs.iter().zip(w.iter()).map(|(d, x)| (*d, *x)).collect(),
            prior_std,
            data_std,
            posterior_std: data_std.map_or(prior_std, |_| {
                (w.transpose() * &post * w)[(0, 0)].max(0.0).sqrt()
            }),
        });
    }
    Ok(out)
}
