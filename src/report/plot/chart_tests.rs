use super::*;
use crate::report::plot::canvas::read_png;

const N: usize = 20;
const FIRST: usize = 4;

/// j = 4: +30 ± 5, j = 5: −12 ± 2, j = 6: NaN, j = 7: 8 with σ NaN,
/// j = 8: 0, then 1.0 without error bars.
fn coefficients() -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![1.0; N];
    let mut s = vec![0.0; N];
    v[..5].copy_from_slice(&[30.0, -12.0, f64::NAN, 8.0, 0.0]);
    s[..4].copy_from_slice(&[5.0, 2.0, 1.0, f64::NAN]);
    (v, s)
}

fn labels(t: &Ticks) -> Vec<String> {
    t.values.iter().map(|&v| t.step.label(v)).collect()
}

fn is_background(p: Rgb) -> bool {
    p == WHITE || p == GRID
}

#[test]
fn written_chart_has_bars_error_bars_and_ticks_in_place() {
    let (v, s) = coefficients();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("chart.png");
    coefficient_chart_png(&p, &v, &s, FIRST, "Front surface coefficients").unwrap();
    let c = read_png(&p);

    // The range −14..35 (bars with error bars) rounds out to −20..40.
    let ticks = covering_ticks(-14.0, 35.0, MAX_TICKS);
    assert_eq!(ticks.values, [-20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0]);
    let l = Layout::new(N, "Front surface coefficients", &labels(&ticks));
    assert_eq!((c.width(), c.height()), (l.width, l.height));
    let row = |v: f64| l.row(&ticks, v) as usize;
    let left = |i: usize| l.bar_x(i) as usize;
    let centre = |i: usize| l.bar_centre(i) as usize;

    assert_eq!(c.get(left(0), row(15.0)), POSITIVE);
    assert_eq!(c.get(left(1), row(-6.0)), NEGATIVE);
    assert!(is_background(c.get(left(0), row(32.0))), "bar 0 too tall");
    assert!(is_background(c.get(left(2), row(5.0))), "NaN drew a bar");
    // Zero line across the NaN gap.
    assert_eq!(c.get(left(2), row(0.0)), BLACK);
    // Error bar of j = 4 reaches 35 and not beyond; its cap spans the bar.
    assert_eq!(c.get(centre(0), row(33.0)), BLACK);
    assert_eq!(c.get(centre(0) + 3, row(35.0)), BLACK);
    assert!(is_background(c.get(centre(0), row(35.0) - 2)));
    assert_eq!(c.get(centre(1), row(-13.5)), BLACK);
    // No error bar where σ is NaN (j = 7) or zero (j = 9).
    assert!(is_background(c.get(centre(3), row(8.0) - 3)));
    assert!(is_background(c.get(centre(5), row(1.0) - 3)));

    // x ticks at j = 5, 10, 15, 20 (bars 1, 6, 11, 16), none at j = 4.
    let tick_y = l.plot_y + PLOT_H + 3;
    for i in 0..N {
        let want = (FIRST + i) % 5 == 0;
        assert_eq!(c.get(centre(i), tick_y) == BLACK, want, "bar {i}");
    }
    // y tick marks left of the frame.
    for &t in &ticks.values {
        assert_eq!(c.get(l.plot_x - 3, row(t)), BLACK, "y tick {t}");
    }
    // The turned axis name left of the labels.
    let ink =
        (l.plot_y..l.plot_y + PLOT_H).any(|y| (MARGIN..MARGIN + 18).any(|x| c.get(x, y) == BLACK));
    assert!(ink, "no y axis name");
}

#[test]
fn many_bars_widen_the_chart_and_labels_do_not_collide() {
    let v: Vec<f64> = (0..231).map(|k| (k as f64 * 0.37).sin() * 40.0).collect();
    let c = render(&v, &[], 1, "231 terms").unwrap();
    assert!(c.width() >= 6 * 231, "{}", c.width());
    let every = x_tick_every(231);
    let widest = text_width("230", TEXT_SCALE);
    assert!(widest + 8 <= MIN_PITCH * every, "x labels would touch");
    // Small counts: one label per bar still fits.
    let pitch = PLOT_MIN_W / 12;
    assert!(text_width("999", TEXT_SCALE) + 8 <= pitch * x_tick_every(12));
}

#[test]
fn all_nan_reads_no_data() {
    let c = render(&[f64::NAN; 3], &[], 1, "none").unwrap();
    let ticks = covering_ticks(-1.0, 1.0, MAX_TICKS);
    let l = Layout::new(3, "none", &labels(&ticks));
    let (cx, cy) = (l.plot_x + l.plot_w / 2, l.plot_y + PLOT_H / 4);
    let ink = (cy - 7..cy + 7).any(|y| (cx - 41..cx + 41).any(|x| c.get(x, y) == BLACK));
    assert!(ink, "no 'no data' note");
}

#[test]
fn bad_input_is_named() {
    let err = render(&[1.0, 2.0], &[0.1], 1, "t").unwrap_err();
    assert!(
        matches!(
            err,
            PlotError::LengthMismatch {
                argument: "std",
                expected: 2,
                found: 1
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("`std`"), "{err}");
    let err = render(&[], &[], 1, "t").unwrap_err();
    assert!(
        matches!(err, PlotError::Empty { argument: "values" }),
        "{err}"
    );
    let err = render(&vec![0.0; MAX_BARS + 1], &[], 1, "t").unwrap_err();
    assert!(matches!(err, PlotError::TooMany { .. }), "{err}");
    let p = Path::new("/nonexistent-dir-for-mfd-test/chart.png");
    let err = coefficient_chart_png(p, &[1.0], &[], 1, "t").unwrap_err();
    assert!(
        err.to_string()
            .contains("/nonexistent-dir-for-mfd-test/chart.png"),
        "{err}"
    );
}
