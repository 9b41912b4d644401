//! How many Zernike terms the data support: the Bayesian information
//! criterion over nested models (Noll orders), evaluated from one Cholesky
//! factor of the normal equations at the largest model's solution.
//!
//! Linearised at the solution `x*`, χ²(x) = χ²_min + (x − x*)ᵀA(x − x*).
//! With the columns ordered so that the candidate's dropped terms come last
//! and `A = LLᵀ`, the best model with those terms at zero has
//! χ² = χ²_min + Σ_{i in tail} (Lᵀx*)_i² — every candidate from one factor.
//! BIC = χ² + p ln N when σ is known (the spectral solver's), else
//! N ln(χ²/N) + p ln N with the scale estimated from the residuals.

use nalgebra::{DMatrix, DVector};

use super::problem::{Layout, Normal};
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::optics::zernike::terms_up_to_order;
use crate::optics::zernike::ZernikeSurface;

/// The criterion in words, for reports (`summary.json`).
pub const CRITERION: &str = "BIC = chi2 + p ln N over nested Noll orders (N ln(chi2/N) + p ln N \
     when sigma is unknown)";

/// The term count chosen for one surface, with the criterion's values.
#[derive(Debug, Clone, PartialEq)]
pub struct TermChoice {
    /// Chosen number of terms (Noll 1..=terms).
    pub terms: usize,
    /// `(terms, BIC)` of every candidate.
    pub candidates: Vec<(usize, f64)>,
    /// The RMS over the element's outline of what the dropped terms hold,
    /// as the largest model estimates it, nm ([`dropped_rms_nm`]): the
    /// truncation's part of the expected error, 0 when nothing is dropped.
    pub dropped_rms_nm: f64,
}

/// The RMS over `outline` (plane removed) that the terms beyond `keep`
/// of the largest model's surface `c` may hold, with that model's
/// covariance `cov` of `c` (nm²). In the set orthonormal over the outline
/// the dropped energy `Σ_{k ≥ keep} a_k²` is estimated without bias by
/// `U = Σ (â_k² − σ_k²)` (`E[â²] = a² + σ²`), whose spread is
/// `sd(U)² = Σ (2σ_k⁴ + 4 a_k² σ_k²)`; the truncation reported is
/// `√(max(U, 0) + sd(U))`: what the dropped terms hold, or, where the data
/// cannot see them, what they cannot rule out (a surface cut to its plane
/// by the criterion would otherwise claim no error at all). The model
/// error that a choice of fewer terms leaves and that no σ of the kept
/// terms shows (the spec's "model error the program estimates").
pub fn dropped_rms_nm(
    outline: &crate::optics::outline::Outline,
    c: &[f64],
    cov: &DMatrix<f64>,
    keep: usize,
) -> f64 {
    if keep >= c.len() {
        return 0.0;
    }
    let Ok(q) = outline.orthonormal(c.len()) else {
        return 0.0;
    };
    let a = q.coefficients(c);
    let s = q.covariance(cov);
    let (mut u, mut var) = (0.0, 0.0);
    for k in keep..a.len() {
        let v = s[(k, k)].max(0.0);
        let seen = a[k] * a[k] - v;
        u += seen;
        var += 2.0 * v * v + 4.0 * seen.max(0.0) * v;
    }
    (u.max(0.0) + var.sqrt()).sqrt()
}

/// Candidate term counts: every full radial order below `max`, and `max`.
pub fn candidates(max: usize) -> Vec<usize> {
    let mut out: Vec<usize> = (1..)
        .map(terms_up_to_order)
        .take_while(|&t| t < max)
        .collect();
    out.push(max);
    out
}

/// Chooses the term count of the front (`back` false) or back surface.
/// `x` holds the free coefficients in `layout`'s column order.
pub fn choose_terms(
    normal: &Normal,
    layout: &Layout,
    x: &DVector<f64>,
    back: bool,
    sigma_known: bool,
) -> Option<TermChoice> {
    let p = layout.columns();
    let max = if back {
        layout.back_terms
    } else {
        layout.front_terms
    };
    let col = |k: usize| {
        if back {
            layout.back_col(k)
        } else {
            layout.front_col(k)
        }
    };
    // Columns of the chosen surface in Noll order, last; the rest first.
    let mine: Vec<usize> = (0..max).filter_map(col).collect();
    let mut order: Vec<usize> = (0..p).filter(|c| !mine.contains(c)).collect();
    order.extend(&mine);
    let a = DMatrix::from_fn(p, p, |i, j| normal.a[(order[i], order[j])]);
    let xp = DVector::from_fn(p, |i, _| x[order[i]]);
    let l = a.cholesky()?.unpack();
    let y = l.transpose() * xp;
    let n = normal.n_resid as f64;
    let first_free = max - mine.len();
    let candidates: Vec<(usize, f64)> = candidates(max)
        .into_iter()
        .filter(|&t| t > first_free)
        .map(|t| {
            let dropped = max - t;
            let tail: f64 = y.iter().rev().take(dropped).map(|v| v * v).sum();
            let chi2 = (normal.chi2 + tail).max(f64::MIN_POSITIVE);
            let params = (p - dropped) as f64;
            let fit = if sigma_known {
                chi2
            } else {
                n * (chi2 / n).ln()
            };
            (t, fit + params * n.ln())
        })
        .collect();
    let best = candidates
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|c| c.0)?;
    Some(TermChoice {
        terms: best,
        candidates,
        dropped_rms_nm: 0.0,
    })
}

/// Each choice's [`TermChoice::dropped_rms_nm`], from the largest model's
/// surfaces and covariance (`normal`, scaled as the solution's covariance is).
pub(super) fn dropped(
    plate: &Plate,
    layout: &Layout,
    normal: &Normal,
    station: &Station,
    sigma_known: bool,
    f: &mut TermChoice,
    b: Option<&mut TermChoice>,
) {
    let Some(inv) = normal.a.clone().try_inverse() else {
        return;
    };
    let red = normal.chi2 / normal.n_resid.saturating_sub(layout.columns()).max(1) as f64;
    let scale = if sigma_known { red.max(1.0) } else { red };
    let outline = station.element.outline();
    let one = |surface: &ZernikeSurface, n: usize, col: &dyn Fn(usize) -> Option<usize>, keep| {
        let cov = DMatrix::from_fn(n, n, |i, j| match (col(i), col(j)) {
            (Some(a), Some(b)) => inv[(a, b)] * scale,
            _ => 0.0,
        });
        dropped_rms_nm(&outline, surface.coefficients_nm(), &cov, keep)
    };
    f.dropped_rms_nm = one(
        &plate.front,
        layout.front_terms,
        &|k| layout.front_col(k),
        f.terms,
    );
    if let Some(b) = b {
        b.dropped_rms_nm = one(
            &plate.back,
            layout.back_terms,
            &|k| layout.back_col(k),
            b.terms,
        );
    }
}
