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
use crate::optics::zernike::terms_up_to_order;

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
    })
}
