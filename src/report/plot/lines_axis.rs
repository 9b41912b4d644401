//! The axes of line plots: linear on 1-2-5 steps covering the data, or
//! logarithmic over whole decades with ticks at powers of ten (and at 2 and
//! 5 times them when the axis spans at most two decades).

use super::ticks::covering_ticks;

/// Decades up to which a log axis also gets ticks at 2 and 5 × 10ⁿ.
const FINE_DECADES: f64 = 2.0;
/// Exponents within this of an integer count as on it, so that
/// `log10(1000.0)` rounding to 2.9999999999999996 neither adds a decade.
const EXP_EDGE: f64 = 1e-9;

/// One axis: the range it shows and its labelled ticks.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Axis {
    log: bool,
    /// Ends of the axis: values (linear) or base-10 exponents (log).
    lo: f64,
    hi: f64,
    /// Tick values, increasing, all inside the axis.
    pub ticks: Vec<f64>,
    /// One label per tick.
    pub labels: Vec<String>,
}

/// Whether `v` can be placed on an axis: finite, and positive on a log
/// axis.
pub(super) fn usable(v: f64, log: bool) -> bool {
    v.is_finite() && (!log || v > 0.0)
}

impl Axis {
    /// An axis covering the usable `values` with at most about `max_ticks`
    /// ticks; with none usable, 0..1 (linear) or 1..10 (log).
    pub fn new(values: impl IntoIterator<Item = f64>, log: bool, max_ticks: usize) -> Self {
        let range = values
            .into_iter()
            .filter(|&v| usable(v, log))
            .fold(None, |r: Option<(f64, f64)>, v| {
                Some(r.map_or((v, v), |(a, b)| (a.min(v), b.max(v))))
            });
        if log {
            Self::logarithmic(range.unwrap_or((1.0, 10.0)), max_ticks)
        } else {
            Self::linear(range.unwrap_or((0.0, 1.0)), max_ticks)
        }
    }

    fn linear((lo, hi): (f64, f64), max_ticks: usize) -> Self {
        let t = covering_ticks(lo, hi, max_ticks);
        Self {
            log: false,
            lo: t.lo(),
            hi: t.hi(),
            labels: t.values.iter().map(|&v| t.step.label(v)).collect(),
            ticks: t.values,
        }
    }

    fn logarithmic((lo, hi): (f64, f64), max_ticks: usize) -> Self {
        let e0 = (lo.log10() + EXP_EDGE).floor();
        let e1 = (hi.log10() - EXP_EDGE).ceil().max(e0 + 1.0);
        let (e0, e1, marks) = if e1 - e0 <= FINE_DECADES {
            let mut marks: Vec<(u8, i32)> = (e0 as i32..e1 as i32)
                .flat_map(|e| [(1, e), (2, e), (5, e)])
                .collect();
            marks.push((1, e1 as i32));
            (e0, e1, marks)
        } else {
            // Every decade, or every second, fifth, tenth when there are
            // many, the axis widened to whole steps.
            let t = covering_ticks(e0, e1, max_ticks);
            let (e0, e1) = if t.step.value() >= 1.0 {
                (t.lo(), t.hi())
            } else {
                (e0, e1)
            };
            let step = t.step.value().max(1.0);
            let n = ((e1 - e0) / step).round() as i32;
            let marks = (0..=n)
                .map(|k| (1, (e0 + f64::from(k) * step) as i32))
                .collect();
            (e0, e1, marks)
        };
        Self {
            log: true,
            lo: e0,
            hi: e1,
            ticks: marks.iter().map(|&(m, e)| times_ten_to(m, e)).collect(),
            labels: marks.iter().map(|&(m, e)| log_label(m, e)).collect(),
        }
    }

    /// Where `v` falls along the axis, 0 at the low end and 1 at the high
    /// end; `None` if it is not [`usable`].
    pub fn frac(&self, v: f64) -> Option<f64> {
        if !usable(v, self.log) {
            return None;
        }
        let t = if self.log { v.log10() } else { v };
        Some((t - self.lo) / (self.hi - self.lo))
    }
}

/// `m`·10^`e`, the nearest double to the decimal (0.002, not 0.0020000000000000005).
fn times_ten_to(m: u8, e: i32) -> f64 {
    if e >= 0 {
        f64::from(m) * 10f64.powi(e)
    } else {
        f64::from(m) / 10f64.powi(-e)
    }
}

/// "0.002", "5", "200"; "1e3", "5e-4" beyond that.
fn log_label(m: u8, e: i32) -> String {
    if (-3..=2).contains(&e) {
        format!("{:.*}", (-e).max(0) as usize, times_ten_to(m, e))
    } else {
        format!("{m}e{e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axis_over_three_decades_labels_powers_of_ten() {
        let a = Axis::new([1.0, 1000.0], true, 7);
        assert_eq!(a.labels, ["1", "10", "100", "1e3"]);
        assert_eq!(a.ticks, [1.0, 10.0, 100.0, 1000.0]);
        // Equal ratios are equal distances.
        assert!((a.frac(10.0).unwrap() - 1.0 / 3.0).abs() < 1e-12);
        assert!((a.frac(100.0).unwrap() - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn short_log_axes_get_2_and_5() {
        let a = Axis::new([0.15, 9.0], true, 7);
        let want = ["0.1", "0.2", "0.5", "1", "2", "5", "10"];
        assert_eq!(a.labels, want);
        let a = Axis::new([3e-4, 7e-4], true, 7);
        assert_eq!(a.labels, ["1e-4", "2e-4", "5e-4", "0.001"]);
        assert_eq!(a.ticks[3], 0.001);
    }

    #[test]
    fn long_log_axes_thin_their_decades() {
        let a = Axis::new([1e-6, 1e6], true, 7);
        let want = ["1e-6", "1e-4", "0.01", "1", "100", "1e4", "1e6"];
        assert_eq!(a.labels, want);
        // Thirteen decades widen to fifteen, in steps of five.
        let a = Axis::new([1e-6, 1e7], true, 6);
        let want = ["1e-10", "1e-5", "1", "1e5", "1e10"];
        assert_eq!(a.labels, want);
    }

    #[test]
    fn log_axes_skip_non_positive_values() {
        let a = Axis::new([-5.0, 0.0, f64::NAN, 2.0, 8.0], true, 7);
        assert_eq!((a.lo, a.hi), (0.0, 1.0));
        assert_eq!(a.frac(0.0), None);
        assert_eq!(a.frac(-1.0), None);
        // A single power of ten still spans a decade.
        let a = Axis::new([100.0], true, 7);
        assert_eq!((a.lo, a.hi), (2.0, 3.0));
    }

    #[test]
    fn linear_axes_cover_the_data() {
        let a = Axis::new([0.3, f64::INFINITY, 12.2], false, 7);
        assert!(a.frac(0.3).unwrap() >= 0.0 && a.frac(12.2).unwrap() <= 1.0);
        assert_eq!(a.labels.len(), a.ticks.len());
        let empty = Axis::new([f64::NAN], false, 7);
        assert_eq!((empty.lo, empty.hi), (0.0, 1.0));
    }
}
