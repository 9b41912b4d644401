//! Two starts of the outer iteration. Where the reflections lie within a
//! bin of each other the global likelihood has more than one maximum: on
//! a 1.05 mm plate the fit started from the per-pixel surfaces converged,
//! on eight noise draws, to surfaces 2.8× their σ from the truth (48 nm
//! against 17 nm reported), a consistent bias in the front-against-back
//! terms while its scatter matched its σ; started from the truth the same
//! data gave 14 nm against 16 nm, at a likelihood higher by ~960 in
//! `Σ N ln RSS`. Its covariance, the curvature at the maximum it found, is
//! honest about the noise and blind to the other maxima.
//!
//! On a narrow rectangle (8.1 mm, 400 frames) the per-pixel start led to
//! 36 terms per face and a maximum less likely than the 28-term one from
//! the plate as made, whose surfaces over the outline were up to 8× their
//! reported error (594 nm against 71 nm on one noise draw).
//!
//! So where the fit started from the per-pixel surfaces, it is run again
//! from the plate as made (the station's nominal surfaces) and the two
//! answers are compared: the same point (within [`SAME_POINT_SIGMA`]) is
//! kept; distinct points are told apart by the likelihood over the pixels
//! both fitted, the higher kept where the difference exceeds
//! [`CLEAR_PREFERENCE`]; otherwise the data do not single out one, and
//! the surfaces are withheld ([`Starts::decided`]).

use std::collections::HashMap;

use super::Fitted;
use crate::solve::surfaces::report::REMOVED_TERMS;

/// Two answers closer than this (RMS over Noll 4+ of their difference over
/// the larger σ of each coefficient) are one maximum: the iteration stops
/// when a step is below 0.05σ, so two runs to one fixed point differ by a
/// small fraction of σ; a second maximum lies several σ away (2.8σ RMS in
/// the case above).
pub const SAME_POINT_SIGMA: f64 = 1.0;

/// The difference of `Σ N ln RSS` (−2 ln L up to a constant, the noise
/// profiled out) over the common pixels by which one maximum is preferred:
/// a likelihood ratio of e^12.5, 5σ on one degree of freedom.
pub const CLEAR_PREFERENCE: f64 = 25.0;

/// What the second start showed.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Starts {
    /// RMS over Noll 4+ (front and back) of the two answers' difference,
    /// each coefficient over the larger of its two σ.
    pub difference_sigma: f64,
    /// `Σ N ln RSS` of the answer from the per-pixel surfaces minus that
    /// from the plate as made, over the pixels both fitted, each fitted
    /// coefficient priced at ln(observations) as the term criterion prices
    /// it (positive: the plate as made's answer is the more likely).
    pub objective_difference: f64,
    /// Pixels both fitted.
    pub pixels_compared: usize,
    /// Whether each run met its step criterion: from the per-pixel
    /// surfaces, from the plate as made.
    pub converged: [bool; 2],
    /// The answer kept: "per-pixel start" or "plate as made".
    pub kept: String,
    /// Whether the data single out the kept answer (false: two maxima
    /// within [`CLEAR_PREFERENCE`] of each other, the surfaces withheld).
    pub decided: bool,
}

impl Starts {
    /// Why the surfaces are withheld, where they are.
    pub fn withheld_because(&self) -> Option<String> {
        (!self.decided).then(|| {
            format!(
                "the surface-domain fit reaches two different answers from the per-pixel \
                 surfaces and from the plate as made ({:.1} σ apart, RMS over the terms), \
                 and the frames favour neither (their likelihoods differ by {:.1} in \
                 Σ N ln RSS over {} pixels, under the {CLEAR_PREFERENCE} that would decide): \
                 the reflections are too close for this schedule to pin the surfaces down",
                self.difference_sigma,
                self.objective_difference.abs(),
                self.pixels_compared
            )
        })
    }
}

/// `a` (from the per-pixel surfaces) against `b` (from the plate as made):
/// the one kept, and the comparison.
pub(super) fn choose(a: Fitted, b: Fitted) -> (Fitted, Starts) {
    let difference_sigma = difference_sigma(&a, &b);
    let objective: HashMap<usize, f64> = b.pix.iter().map(|x| (x.q, x.objective())).collect();
    let (mut da, mut db, mut n) = (0.0, 0.0, 0);
    for x in &a.pix {
        if let Some(ob) = objective.get(&x.q) {
            da += x.objective();
            db += ob;
            n += 1;
        }
    }
    // Each coefficient's price in the likelihood (the criterion's, BIC:
    // ln of the observations compared), so that more terms do not win by
    // their number alone.
    let observations: usize = a.pix.iter().map(|x| 2 * x.p.k).sum();
    let price = (observations.max(1) as f64).ln();
    let objective_difference =
        da - db + price * (coefficients(&a) as f64 - coefficients(&b) as f64);
    let converged = [a.converged, b.converged];
    let (keep_b, decided) = decide(difference_sigma, objective_difference, converged);
    let starts = Starts {
        difference_sigma,
        objective_difference,
        pixels_compared: n,
        converged,
        kept: if keep_b {
            "plate as made"
        } else {
            "per-pixel start"
        }
        .into(),
        decided,
    };
    log::info!("surface-domain fit from two starts: {starts:?}");
    (if keep_b { b } else { a }, starts)
}

/// Which answer to keep, and whether the data single it out: the more
/// likely (with its terms' price) where the likelihoods differ by more than
/// [`CLEAR_PREFERENCE`]; else the per-pixel start's where the two are one
/// point; else the converged one where only one converged (the other was
/// still on its way); else neither is singled out. Returns (keep the plate
/// as made's answer, decided).
fn decide(difference_sigma: f64, objective_difference: f64, converged: [bool; 2]) -> (bool, bool) {
    if objective_difference.abs() > CLEAR_PREFERENCE {
        (objective_difference > 0.0, true)
    } else if difference_sigma < SAME_POINT_SIGMA {
        (false, true)
    } else if converged[0] != converged[1] {
        (converged[1], true)
    } else {
        (objective_difference > 0.0, false)
    }
}

/// The fitted coefficients of front and (where fitted) back.
fn coefficients(f: &Fitted) -> usize {
    let s = &f.solution;
    s.front.coefficients_nm().len()
        + if s.back_fitted {
            s.back.coefficients_nm().len()
        } else {
            0
        }
}

/// RMS over Noll 4+ of front and back of `(a − b) / max(σa, σb)`.
fn difference_sigma(a: &Fitted, b: &Fitted) -> f64 {
    let (sa, sb) = (&a.solution, &b.solution);
    let mut faces = vec![(
        sa.front.coefficients_nm(),
        sb.front.coefficients_nm(),
        &sa.front_std_nm,
        &sb.front_std_nm,
    )];
    if sa.back_fitted && sb.back_fitted {
        faces.push((
            sa.back.coefficients_nm(),
            sb.back.coefficients_nm(),
            &sa.back_std_nm,
            &sb.back_std_nm,
        ));
    }
    let (mut sum, mut n) = (0.0, 0usize);
    for (ca, cb, ua, ub) in faces {
        for j in REMOVED_TERMS..ca.len().max(cb.len()) {
            let at = |c: &[f64], j: usize| c.get(j).copied().unwrap_or(0.0);
            let s = at(ua, j).max(at(ub, j));
            if s > 0.0 {
                sum += ((at(ca, j) - at(cb, j)) / s).powi(2);
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_more_likely_answer_is_kept_and_two_equal_maxima_are_not_decided() {
        // A clear likelihood difference decides, either way, whatever the
        // distance between the answers.
        assert_eq!(decide(0.5, 49.0, [true, true]), (true, true));
        assert_eq!(decide(3.0, -186.0, [true, true]), (false, true));
        // One point: the first answer.
        assert_eq!(decide(0.2, 3.0, [true, true]), (false, true));
        // Apart, equally likely, one not at a fixed point: the converged.
        assert_eq!(decide(2.0, 3.0, [false, true]), (true, true));
        assert_eq!(decide(2.0, -3.0, [true, false]), (false, true));
        // Apart, equally likely, both converged: not decided.
        assert_eq!(decide(2.0, 10.0, [true, true]), (true, false));
        assert_eq!(decide(2.0, -10.0, [true, true]), (false, false));
    }

    #[test]
    fn an_undecided_comparison_withholds_with_its_numbers() {
        let mut s = Starts {
            difference_sigma: 2.5,
            objective_difference: -7.0,
            pixels_compared: 700,
            converged: [true, true],
            kept: "per-pixel start".into(),
            decided: false,
        };
        let why = s.withheld_because().expect("withheld");
        assert!(why.contains("2.5 σ apart") && why.contains("7.0") && why.contains("700 pixels"));
        s.decided = true;
        assert_eq!(s.withheld_because(), None);
    }
}
