//! Axis ticks on 1-2-5 steps and their labels.

/// A tick spacing `mantissa`×10^`exp` with `mantissa` 1, 2 or 5.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    mantissa: u8,
    exp: i32,
}

/// Ticks closer than this fraction of a step to a range end count as on it,
/// so that rounding in `lo / step` neither drops nor adds one ...
const EDGE: f64 = 1e-9;
/// ... plus this fraction of `lo / step` itself, whose rounding error (a few
/// ulps, ~1e-16 relative) grows with it when the range sits far from zero.
const EDGE_REL: f64 = 1e-12;

impl Step {
    /// The `k`-th multiple of the step, computed so that decimal steps give
    /// the nearest double to the decimal value (0.6, not 0.6000000000000001).
    pub fn at(self, k: f64) -> f64 {
        let m = k * f64::from(self.mantissa);
        if self.exp >= 0 {
            m * 10f64.powi(self.exp)
        } else {
            m / 10f64.powi(-self.exp)
        }
    }

    /// The spacing as a number.
    pub fn value(self) -> f64 {
        self.at(1.0)
    }

    /// The next larger 1-2-5 step.
    fn next(self) -> Self {
        match self.mantissa {
            1 => Self {
                mantissa: 2,
                ..self
            },
            2 => Self {
                mantissa: 5,
                ..self
            },
            _ => Self {
                mantissa: 1,
                exp: self.exp + 1,
            },
        }
    }

    /// A step at or below `span / intervals`, to grow from.
    fn below(span: f64, intervals: usize) -> Self {
        let raw = span / intervals.max(1) as f64;
        Self {
            mantissa: 1,
            exp: raw.log10().floor() as i32 - 1,
        }
    }

    /// Multiples `k` of the step inside [`lo`, `hi`] (inward) or covering it
    /// (outward), as the first and last `k`.
    fn multiples(self, lo: f64, hi: f64, outward: bool) -> (f64, f64) {
        let s = self.value();
        let (a, b) = (lo / s, hi / s);
        let (ta, tb) = (EDGE + EDGE_REL * a.abs(), EDGE + EDGE_REL * b.abs());
        if outward {
            ((a + ta).floor(), (b - tb).ceil())
        } else {
            ((a - ta).ceil(), (b + tb).floor())
        }
    }

    /// The label of `value`, a multiple of this step: fixed-point with as
    /// many decimals as the step needs, or scientific for very large or
    /// very small steps.
    pub fn label(self, value: f64) -> String {
        let v = if value == 0.0 { 0.0 } else { value }; // no "-0"
        if self.exp < -4 || self.exp > 5 {
            format!("{v:e}")
        } else {
            format!("{v:.*}", (-self.exp).max(0) as usize)
        }
    }
}

/// Ticks from [`covering_ticks`]: the values and their spacing.
#[derive(Debug, Clone, PartialEq)]
pub struct Ticks {
    /// Tick values, increasing; the first is at or below the range's low
    /// end and the last at or above its high end.
    pub values: Vec<f64>,
    /// The spacing.
    pub step: Step,
}

impl Ticks {
    /// The lowest tick.
    pub fn lo(&self) -> f64 {
        self.values[0]
    }

    /// The highest tick.
    pub fn hi(&self) -> f64 {
        self.values[self.values.len() - 1]
    }
}

/// The smallest step whose multiples (inside or covering the range) number
/// at most `max_ticks`, with those multiples.
fn fit_step(lo: f64, hi: f64, max_ticks: usize, outward: bool) -> (Step, f64, f64) {
    let max_ticks = max_ticks.max(2);
    let mut step = Step::below(hi - lo, max_ticks - 1);
    loop {
        let (k0, k1) = step.multiples(lo, hi, outward);
        if k1 - k0 + 1.0 <= max_ticks as f64 {
            return (step, k0, k1);
        }
        step = step.next();
    }
}

/// At most `max_ticks` (at least 2 are allowed) "nice" values inside
/// [`lo`, `hi`]: multiples of the smallest 1, 2 or 5 × 10ⁿ spacing that
/// keeps their number within `max_ticks`.
///
/// The ends may be given in either order. Equal ends give that one value;
/// a non-finite end gives no ticks.
///
/// ```
/// assert_eq!(mfd::report::plot::nice_ticks(0.0, 1.0, 6), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
/// assert_eq!(mfd::report::plot::nice_ticks(-3.0, 7.5, 5), vec![-2.0, 0.0, 2.0, 4.0, 6.0]);
/// ```
pub fn nice_ticks(lo: f64, hi: f64, max_ticks: usize) -> Vec<f64> {
    if !lo.is_finite() || !hi.is_finite() {
        return Vec::new();
    }
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if lo == hi {
        return vec![lo];
    }
    let (step, k0, k1) = fit_step(lo, hi, max_ticks, false);
    let n = (k1 - k0 + 1.0).max(0.0) as usize;
    (0..n).map(|i| step.at(k0 + i as f64)).collect()
}

/// At most `max_ticks` nice ticks whose first and last enclose [`lo`, `hi`]
/// (ends in order, finite): an axis range. A zero-width range is widened by
/// 10 % of its value each way, or to ±1 at zero.
pub fn covering_ticks(lo: f64, hi: f64, max_ticks: usize) -> Ticks {
    let (mut lo, mut hi) = (lo.min(hi), lo.max(hi));
    if lo == hi {
        let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        lo -= d;
        hi += d;
    }
    let (step, k0, k1) = fit_step(lo, hi, max_ticks, true);
    let n = (k1 - k0 + 1.0) as usize;
    Ticks {
        values: (0..n).map(|i| step.at(k0 + i as f64)).collect(),
        step,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_interval_in_fifths() {
        // Decimal multiples are computed as k·m / 10ⁿ, so they equal the
        // literals exactly.
        assert_eq!(nice_ticks(0.0, 1.0, 6), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(nice_ticks(1.0, 0.0, 6), nice_ticks(0.0, 1.0, 6));
        assert_eq!(nice_ticks(0.0, 1.0, 11).len(), 11);
        assert_eq!(nice_ticks(0.0, 1.0, 3), vec![0.0, 0.5, 1.0]);
    }

    #[test]
    fn negative_ranges() {
        assert_eq!(
            nice_ticks(-10.0, -2.0, 5),
            vec![-10.0, -8.0, -6.0, -4.0, -2.0]
        );
        assert_eq!(
            nice_ticks(-45.6, 45.6, 7),
            vec![-40.0, -20.0, 0.0, 20.0, 40.0]
        );
        assert_eq!(nice_ticks(-3.0, 7.5, 5), vec![-2.0, 0.0, 2.0, 4.0, 6.0]);
        assert_eq!(nice_ticks(-3.0, 7.5, 4), vec![0.0, 5.0]);
    }

    #[test]
    fn tiny_and_offset_ranges() {
        assert_eq!(
            nice_ticks(0.0, 1e-3, 6),
            vec![0.0, 2e-4, 4e-4, 6e-4, 8e-4, 1e-3]
        );
        let t = nice_ticks(1.0, 1.001, 6);
        assert_eq!(t, vec![1.0, 1.0002, 1.0004, 1.0006, 1.0008, 1.001]);
    }

    #[test]
    fn constant_and_non_finite_input() {
        assert_eq!(nice_ticks(3.7, 3.7, 6), vec![3.7]);
        assert!(nice_ticks(f64::NAN, 1.0, 6).is_empty());
        assert!(nice_ticks(0.0, f64::INFINITY, 6).is_empty());
    }

    #[test]
    fn count_never_exceeds_the_limit_and_steps_are_1_2_5() {
        for (k, lo) in [-1234.5, -1.0, 0.0, 0.003, 17.0].into_iter().enumerate() {
            for span_exp in -6..6 {
                let hi = lo + 10f64.powi(span_exp) * (1.0 + 0.37 * k as f64);
                for max in 2..10 {
                    let t = nice_ticks(lo, hi, max);
                    assert!(!t.is_empty() && t.len() <= max, "{lo} {hi} {max}: {t:?}");
                    // Slack: the 1e-9 step tolerance plus rounding of lo
                    // itself (1234.5 · 2e-16 ≈ 3e-13 against spans ≥ 1e-6).
                    let slack = 1e-9 * (hi - lo) + 1e-15 * lo.abs();
                    let inside = t.iter().all(|&v| v >= lo - slack && v <= hi + slack);
                    assert!(inside, "{lo} {hi} {max}: {t:?}");
                    if t.len() > 1 {
                        let s = t[1] - t[0];
                        let m = s / 10f64.powf(s.log10().floor());
                        assert!(
                            [1.0, 2.0, 5.0, 10.0].iter().any(|&x| (m - x).abs() < 1e-6),
                            "{s}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn covering_ticks_enclose_the_range() {
        let t = covering_ticks(-45.6, 45.6, 7);
        assert_eq!(t.values, vec![-60.0, -40.0, -20.0, 0.0, 20.0, 40.0, 60.0]);
        let t = covering_ticks(0.0, 0.0, 7);
        assert_eq!((t.lo(), t.hi()), (-1.0, 1.0));
        let t = covering_ticks(-0.3, 12.2, 6);
        assert!(
            t.lo() <= -0.3 && t.hi() >= 12.2 && t.values.len() <= 6,
            "{t:?}"
        );
    }

    #[test]
    fn labels_have_the_step_precision() {
        let t = covering_ticks(0.0, 1.0, 6);
        let labels: Vec<String> = t.values.iter().map(|&v| t.step.label(v)).collect();
        assert_eq!(labels, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        let t = covering_ticks(-100.0, 100.0, 5);
        assert_eq!(t.step.label(-100.0), "-100");
        assert_eq!(t.step.label(-0.0), "0");
        let t = covering_ticks(0.0, 5e-6, 6);
        assert_eq!(t.step.label(t.values[1]), "1e-6");
    }
}
