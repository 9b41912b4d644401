//! The joint covariance of front and back coefficients of a solution: the
//! noise's from the fit (cross block included) plus, with a station
//! uncertainty, the station's `S C Sᵀ` over both surfaces together (the
//! error budget's per-σ columns), so that a figure of `W1 − W2` gets the
//! correlation the two faces share.

use nalgebra::DMatrix;

use super::{figures, FigureInput, Figures};
use crate::budget::Budget;
use crate::optics::station::Station;
use crate::solve::surfaces::SurfaceSolution;

/// What the covariance holds when the station's part is in it.
pub const WITH_STATION: &str = "joint covariance of front and back (cross block included): \
imaging noise and the station's uncertainty";

/// What the covariance holds without a station uncertainty.
pub const NOISE_ONLY: &str = "joint covariance of front and back (cross block included): \
imaging noise alone (no station uncertainty was given)";

/// Why the back has no figures when no back reflection was measured.
pub const NO_BACK: &str = "the back was not reconstructed (no back reflection was measured)";

/// The joint covariance (nm²) of `sol`'s front then back coefficients
/// (all of them; zero rows for fixed ones), with `budget`'s station part
/// where there is one.
pub fn covariance(sol: &SurfaceSolution, budget: Option<&Budget>) -> DMatrix<f64> {
    let nf = sol.front.coefficients_nm().len();
    let nb = sol.back.coefficients_nm().len();
    let col = |i: usize| {
        if i < nf {
            sol.layout.front_col(i)
        } else {
            sol.layout.back_col(i - nf)
        }
    };
    let n = nf + nb;
    let mut c = DMatrix::from_fn(n, n, |r, s| match (col(r), col(s)) {
        (Some(a), Some(b)) if a < sol.covariance.nrows() && b < sol.covariance.ncols() => {
            sol.covariance[(a, b)]
        }
        _ => 0.0,
    });
    if let Some(b) = budget {
        let s = DMatrix::from_fn(n, b.dofs.len(), |i, k| {
            let d = &b.dofs[k];
            let per_unit = if i < nf {
                d.front_nm_per_unit.get(i)
            } else {
                d.back_nm_per_unit.get(i - nf)
            };
            per_unit.copied().unwrap_or(0.0) * d.std
        });
        c += &s * &b.correlation * s.transpose();
    }
    c
}

/// The figures of a solution on `station` (its refractive index), at
/// `wavelength_nm`, with `withheld` the reasons a face is not reported;
/// `None` when the solution's Zernike radius is unusable.
pub fn of_solution(
    sol: &SurfaceSolution,
    budget: Option<&Budget>,
    station: &Station,
    wavelength_nm: f64,
    withheld: &[Option<String>; 2],
) -> Option<Figures> {
    let cov = covariance(sol, budget);
    let back_why = withheld[1]
        .clone()
        .or_else(|| (!sol.back_fitted).then(|| NO_BACK.to_string()));
    let input = FigureInput {
        front_nm: sol.front.coefficients_nm(),
        back_nm: sol.back.coefficients_nm(),
        covariance_nm2: &cov,
        radius_mm: sol.front.basis().radius_mm(),
        refractive_index: station.element.refractive_index,
        wavelength_nm,
        covariance_note: if budget.is_some() {
            WITH_STATION
        } else {
            NOISE_ONLY
        }
        .into(),
        withheld: [withheld[0].clone(), back_why],
    };
    figures(&input).ok()
}
