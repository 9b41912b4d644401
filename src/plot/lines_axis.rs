//! The axes of line plots and where their legend goes: a linear axis spans
//! the data with 5 % head room; a logarithmic one spans whole decades
//! (`plotters` places ticks at the powers of ten).

use std::ops::Range;

use plotters::chart::SeriesLabelPosition;

use super::font;

/// Head room each side of a linear axis, as a fraction of the data span.
const PAD: f64 = 0.05;
/// Exponents within this of an integer count as on it, so that
/// `log10(1000.0)` rounding to 2.9999999999999996 adds no decade.
const EXP_EDGE: f64 = 1e-9;
/// The legend's size as a fraction of the plot area, per side, for
/// choosing its corner: its width, and its height per series plus a frame.
const LEGEND_W: f64 = 0.4;
const LEGEND_ROW_H: f64 = 0.085;
const LEGEND_FRAME_H: f64 = 0.06;
/// Samples per polyline segment when looking for data under a corner.
const SAMPLES: usize = 16;

/// Whether `v` can be placed on an axis: finite, and positive on a log
/// axis.
pub(super) fn usable(v: f64, log: bool) -> bool {
    v.is_finite() && (!log || v > 0.0)
}

/// One axis: what it spans.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct AxisRange {
    log: bool,
    /// Ends of the axis, in data units.
    lo: f64,
    hi: f64,
}

impl AxisRange {
    /// An axis covering the usable `values`; with none usable, 0..1
    /// (linear) or 1..10 (log).
    pub fn new(values: impl IntoIterator<Item = f64>, log: bool) -> Self {
        let range = values
            .into_iter()
            .filter(|&v| usable(v, log))
            .fold(None, |r: Option<(f64, f64)>, v| {
                Some(r.map_or((v, v), |(a, b)| (a.min(v), b.max(v))))
            });
        let (lo, hi) = match (range, log) {
            (None, false) => (0.0, 1.0),
            (None, true) => (1.0, 10.0),
            (Some((a, b)), false) => {
                let pad = if b > a {
                    PAD * (b - a)
                } else if a != 0.0 {
                    0.1 * a.abs()
                } else {
                    1.0
                };
                (a - pad, b + pad)
            }
            (Some((a, b)), true) => {
                let e0 = (a.log10() + EXP_EDGE).floor();
                let e1 = (b.log10() - EXP_EDGE).ceil().max(e0 + 1.0);
                (10f64.powf(e0), 10f64.powf(e1))
            }
        };
        Self { log, lo, hi }
    }

    /// The span to build the axis from.
    pub fn span(&self) -> Range<f64> {
        self.lo..self.hi
    }

    /// Where `v` falls along the axis, 0 at the low end and 1 at the high
    /// end; NaN if it is not [`usable`].
    pub fn frac(&self, v: f64) -> f64 {
        if !usable(v, self.log) {
            return f64::NAN;
        }
        if self.log {
            (v.log10() - self.lo.log10()) / (self.hi.log10() - self.lo.log10())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        }
    }

    /// The tick label of `v`.
    pub fn label(&self, v: f64) -> String {
        if self.log {
            let decades = (self.hi / self.lo).log10();
            font::log_tick_label(v, decades < 1.0 + EXP_EDGE)
        } else {
            // A tick reached by adding steps carries their rounding: one at
            // 1e-12 of the span from zero is zero (a label "-1.6e-17" is noise).
            let span = (self.hi - self.lo).abs();
            let v = if v.abs() <= 1e-12 * span { 0.0 } else { v };
            font::tick_label(v)
        }
    }
}

/// The plot corner (top right, top left, bottom right, bottom left,
/// preferred in that order) whose legend box covers the fewest samples of
/// `polylines`, one per series, in axis fractions (y up).
pub(super) fn legend_corner(polylines: &[Vec<(f64, f64)>]) -> SeriesLabelPosition {
    let h = LEGEND_FRAME_H + LEGEND_ROW_H * polylines.len() as f64;
    let samples: Vec<(f64, f64)> = polylines
        .iter()
        .flat_map(|line| {
            let single = line.iter().map(|&p| (p, p));
            let pairs = line.windows(2).map(|w| (w[0], w[1]));
            single.chain(pairs).flat_map(|(a, b)| {
                (0..=SAMPLES).map(move |k| {
                    let t = k as f64 / SAMPLES as f64;
                    (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
                })
            })
        })
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let count = |x0: f64, y0: f64| {
        let inside =
            |p: &&(f64, f64)| p.0 >= x0 && p.0 <= x0 + LEGEND_W && p.1 >= y0 && p.1 <= y0 + h;
        samples.iter().filter(inside).count()
    };
    let corners = [
        (
            SeriesLabelPosition::UpperRight,
            count(1.0 - LEGEND_W, 1.0 - h),
        ),
        (SeriesLabelPosition::UpperLeft, count(0.0, 1.0 - h)),
        (SeriesLabelPosition::LowerRight, count(1.0 - LEGEND_W, 0.0)),
        (SeriesLabelPosition::LowerLeft, count(0.0, 0.0)),
    ];
    let mut best = 0;
    for (i, c) in corners.iter().enumerate() {
        if c.1 < corners[best].1 {
            best = i;
        }
    }
    corners
        .into_iter()
        .nth(best)
        .map_or(SeriesLabelPosition::UpperRight, |c| c.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axes_span_whole_decades() {
        let a = AxisRange::new([1.0, 1000.0], true);
        assert_eq!(a.span(), 1.0..1000.0);
        // Equal ratios are equal distances.
        assert!((a.frac(10.0) - 1.0 / 3.0).abs() < 1e-12);
        assert!((a.frac(100.0) - 2.0 / 3.0).abs() < 1e-12);
        let a = AxisRange::new([0.15, 9.0], true);
        assert_eq!(a.span(), 0.1..10.0);
        assert_eq!(a.label(1.0), "1");
        assert_eq!(a.label(2.0), "", "no label between decades on a long axis");
        let a = AxisRange::new([3e-4, 7e-4], true);
        assert_eq!((a.lo, a.hi), (1e-4, 1e-3));
        assert_eq!(
            a.label(5e-4),
            "0.0005",
            "a one-decade axis labels its inner ticks"
        );
        assert_eq!(AxisRange::new([1e-6, 1e6], true).label(1e-6), "10⁻⁶");
    }

    #[test]
    fn log_axes_skip_non_positive_values() {
        let a = AxisRange::new([-5.0, 0.0, f64::NAN, 2.0, 8.0], true);
        assert_eq!((a.lo, a.hi), (1.0, 10.0));
        assert!(a.frac(0.0).is_nan());
        assert!(a.frac(-1.0).is_nan());
        // A single power of ten still spans a decade.
        let a = AxisRange::new([100.0], true);
        assert_eq!((a.lo, a.hi), (100.0, 1000.0));
    }

    #[test]
    fn linear_axes_cover_the_data() {
        let a = AxisRange::new([0.3, f64::INFINITY, 12.2], false);
        assert!(a.frac(0.3) > 0.0 && a.frac(12.2) < 1.0);
        assert!((a.frac(0.3) - 0.05 / 1.1).abs() < 1e-12);
        let empty = AxisRange::new([f64::NAN], false);
        assert_eq!((empty.lo, empty.hi), (0.0, 1.0));
        let flat = AxisRange::new([5.0, 5.0], false);
        assert_eq!((flat.lo, flat.hi), (4.5, 5.5));
        assert_eq!(flat.label(5.0), "5");
    }

    #[test]
    fn legend_goes_where_the_data_is_not() {
        let rising = vec![vec![(0.0, 0.0), (1.0, 1.0)]];
        assert!(matches!(
            legend_corner(&rising),
            SeriesLabelPosition::UpperLeft
        ));
        let falling = vec![vec![(0.0, 1.0), (1.0, 0.0)]];
        assert!(matches!(
            legend_corner(&falling),
            SeriesLabelPosition::UpperRight
        ));
        let high = vec![vec![(0.0, 0.95), (1.0, 0.95)]];
        assert!(matches!(
            legend_corner(&high),
            SeriesLabelPosition::LowerRight
        ));
        let none = vec![vec![(f64::NAN, 0.5)]];
        assert!(matches!(
            legend_corner(&none),
            SeriesLabelPosition::UpperRight
        ));
    }
}
