//! The joint covariance of front and back coefficients of a solution: the
//! noise's from the fit (cross block included) plus, with a station
//! uncertainty, the station's `S C Sᵀ` over both surfaces together (the
//! error budget's per-σ columns), so that a figure of `W1 − W2` gets the
//! correlation the two faces share.

use nalgebra::DMatrix;

use super::{figures, FigureInput, Figures, Over};
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
    // Over an outline other than the disk: coefficients and covariance in
    // the set orthonormal over it (`Over`).
    let (nf, nb) = (
        sol.front.coefficients_nm().len(),
        sol.back.coefficients_nm().len(),
    );
    let over = sol
        .outline
        .orthonormal(nf.max(nb))
        .ok()
        .filter(|q| !q.is_identity())
        .map(|set| Over {
            outline: sol.outline.clone(),
            set,
        });
    let (front, back, cov) = match &over {
        None => (
            sol.front.coefficients_nm().to_vec(),
            sol.back.coefficients_nm().to_vec(),
            cov,
        ),
        Some(o) => {
            let lt = o.set.matrix();
            let mut t = DMatrix::zeros(nf + nb, nf + nb);
            t.view_mut((0, 0), (nf, nf))
                .copy_from(&lt.view((0, 0), (nf, nf)));
            t.view_mut((nf, nf), (nb, nb))
                .copy_from(&lt.view((0, 0), (nb, nb)));
            let n = cov.nrows().min(nf + nb);
            let mut c = DMatrix::zeros(nf + nb, nf + nb);
            c.view_mut((0, 0), (n, n))
                .copy_from(&cov.view((0, 0), (n, n)));
            let mut a_f = o.set.coefficients(sol.front.coefficients_nm());
            let mut a_b = o.set.coefficients(sol.back.coefficients_nm());
            a_f.truncate(nf);
            a_b.truncate(nb);
            (a_f, a_b, &t * c * t.transpose())
        }
    };
    let input = FigureInput {
        front_nm: &front,
        back_nm: &back,
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
        over: over.as_ref(),
    };
    figures(&input).ok()
}
