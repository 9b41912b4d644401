//! How good a result is against a truth: the figures `mfd compare`,
//! `mfd tradeoff`, the benchmarks and the tests all quote, computed one way.
//!
//! - Screen points: found fraction (of the pixels whose truth has the
//!   reflection), RMS and worst error in screen px, the RMS of the reported
//!   σ, and RMS(error/σ) per coordinate — which is ≈ 1 when the reported
//!   uncertainty is honest.
//! - Surfaces: the RMS difference over the aperture with piston and tilt
//!   removed (Noll terms are orthonormal in RMS, so it is the root sum of
//!   squared coefficient differences from j = 4).

use crate::solve::surfaces::report::REMOVED_TERMS;

/// Running figures of one reflection's screen points against the truth.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PointScore {
    /// Pixels whose truth has this reflection.
    pub expected: usize,
    /// Of those, pixels where a point was reported.
    pub found: usize,
    sum_e2: f64,
    worst: f64,
    sum_s2: f64,
    sum_z2: f64,
    with_std: usize,
}

impl PointScore {
    /// Adds one pixel: `truth` (NaN when the reflection does not exist
    /// there: not counted), `ours` (NaN when not found) and optionally the
    /// reported σ of u and v.
    pub fn add(&mut self, ours: [f64; 2], truth: [f64; 2], std: Option<[f64; 2]>) {
        if truth[0].is_nan() || truth[1].is_nan() {
            return;
        }
        self.expected += 1;
        if ours[0].is_nan() || ours[1].is_nan() {
            return;
        }
        self.found += 1;
        let (du, dv) = (ours[0] - truth[0], ours[1] - truth[1]);
        self.sum_e2 += du * du + dv * dv;
        self.worst = self.worst.max(du.hypot(dv));
        if let Some([su, sv]) = std {
            self.with_std += 1;
            self.sum_s2 += su * su + sv * sv;
            self.sum_z2 += (du / su).powi(2) + (dv / sv).powi(2);
        }
    }

    /// Found over expected (NaN when nothing was expected).
    pub fn found_fraction(&self) -> f64 {
        self.found as f64 / self.expected as f64
    }

    /// RMS distance from the truth of the found points, screen px.
    pub fn rms_error_px(&self) -> f64 {
        (self.sum_e2 / self.found as f64).sqrt()
    }

    /// Largest distance from the truth, screen px (0 when none found).
    pub fn worst_px(&self) -> f64 {
        self.worst
    }

    /// RMS of the reported σ as a distance (`sqrt(σu² + σv²)`), screen px;
    /// NaN without σ.
    pub fn rms_reported_px(&self) -> f64 {
        (self.sum_s2 / self.with_std as f64).sqrt()
    }

    /// RMS of error/σ per coordinate; ≈ 1 when the reported σ is honest;
    /// NaN without σ.
    pub fn rms_error_over_sigma(&self) -> f64 {
        (self.sum_z2 / (2.0 * self.with_std as f64)).sqrt()
    }
}

/// Scores of S1 and S2 of a `[rows, cols, 2, 2]` array against a truth of
/// the same layout, optionally with the reported σ (same layout).
///
/// # Panics
/// When the arrays' lengths differ or are not a multiple of 4 (callers check
/// the shapes they read).
pub fn score_screen_points(ours: &[f64], truth: &[f64], std: Option<&[f64]>) -> [PointScore; 2] {
    assert_eq!(
        ours.len(),
        truth.len(),
        "screen points and truth differ in length"
    );
    assert_eq!(ours.len() % 4, 0, "screen points: [.., 2, 2] expected");
    if let Some(s) = std {
        assert_eq!(s.len(), ours.len(), "σ and screen points differ in length");
    }
    let mut out = [PointScore::default(); 2];
    for p in 0..ours.len() / 4 {
        for (k, score) in out.iter_mut().enumerate() {
            let at = 4 * p + 2 * k;
            score.add(
                [ours[at], ours[at + 1]],
                [truth[at], truth[at + 1]],
                std.map(|s| [s[at], s[at + 1]]),
            );
        }
    }
    out
}

/// RMS difference (nm) of two coefficient sets over the unit disk with
/// piston and tilt removed: the root sum of squared differences from j = 4
/// (Noll terms are orthonormal in RMS); missing terms count as 0.
pub fn rms_difference_nm(a: &[f64], b: &[f64]) -> f64 {
    (REMOVED_TERMS..a.len().max(b.len()))
        .map(|k| a.get(k).copied().unwrap_or(0.0) - b.get(k).copied().unwrap_or(0.0))
        .map(|d| d * d)
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_score_counts_and_scales() {
        let nan = f64::NAN;
        // Two pixels: S1 found in both (errors (3, 4) → 5 px and 0), S2
        // missing in one and absent from the truth in the other.
        let truth = [0.0, 0.0, 1.0, 1.0, 10.0, 10.0, nan, nan];
        let ours = [3.0, 4.0, nan, nan, 10.0, 10.0, 5.0, 5.0];
        let std = [3.0, 4.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        let [s1, s2] = score_screen_points(&ours, &truth, Some(&std));
        assert_eq!((s1.expected, s1.found), (2, 2));
        assert_eq!((s2.expected, s2.found), (1, 0));
        assert!((s1.rms_error_px() - (25.0f64 / 2.0).sqrt()).abs() < 1e-12);
        assert_eq!(s1.worst_px(), 5.0);
        // error/σ: (1, 1) in the first pixel, (0, 0) in the second.
        assert!((s1.rms_error_over_sigma() - (2.0f64 / 4.0).sqrt()).abs() < 1e-12);
        assert!((s1.rms_reported_px() - ((25.0f64 + 2.0) / 2.0).sqrt()).abs() < 1e-12);
        assert_eq!(s2.found_fraction(), 0.0);
        assert!(s2.rms_error_px().is_nan());
    }

    #[test]
    fn surface_difference_ignores_piston_and_tilt() {
        let a = [5.0, 1.0, 2.0, 3.0, 4.0];
        let b = [0.0, 0.0, 0.0, 0.0];
        assert!((rms_difference_nm(&a, &b) - 5.0).abs() < 1e-12);
    }
}
