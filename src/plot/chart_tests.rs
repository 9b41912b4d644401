use super::*;
use crate::plot::test_util::{column, is_dark, row, Pixels, Rgb, WHITE};

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

fn rgb(c: RGBColor) -> Rgb {
    [c.0, c.1, c.2]
}

fn is_background(p: Rgb) -> bool {
    p == WHITE || p == rgb(GRID)
}

#[test]
fn written_chart_has_bars_error_bars_and_ticks_in_place() {
    let (v, s) = coefficients();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("chart.png");
    let title = "Front surface Zernike coefficients (Noll j ≥ 4), error bars ±1σ";
    coefficient_chart_png(&p, &v, &s, FIRST, title).unwrap();
    let c = Pixels::read_png(&p);
    let chart = Chart::new(&v, &s, FIRST, title).unwrap();
    assert_eq!((c.width as u32, c.height as u32), chart.size);

    // The range −14..35 (bars with error bars) with 6 % head room.
    let pad = 0.06 * 49.0;
    assert_eq!(chart.y, (-14.0 - pad, 35.0 + pad));
    let (x0, y0, w, h) = chart.plot;
    let y = |v: f64| row(v, chart.y, y0, h);
    let x = |j: f64| column(j, chart.x(), x0, w);
    let left = |i: usize| x((FIRST + i) as f64 - 0.3);
    let centre = |i: usize| x((FIRST + i) as f64);

    // A positive coefficient's bar stands above the zero line, a negative
    // one's hangs below it.
    assert_eq!(c.get(left(0), y(15.0)), rgb(POSITIVE));
    assert!(
        is_background(c.get(left(0), y(-6.0))),
        "positive bar below zero"
    );
    assert_eq!(c.get(left(1), y(-6.0)), rgb(NEGATIVE));
    assert!(
        is_background(c.get(left(1), y(6.0))),
        "negative bar above zero"
    );
    assert!(is_background(c.get(left(0), y(32.0))), "bar 0 too tall");
    assert!(is_background(c.get(left(2), y(5.0))), "NaN drew a bar");
    // Zero line across the NaN gap.
    assert!(is_dark(c.get(left(2), y(0.0))));
    // Error bar of j = 4 reaches 35 and not beyond; its cap spans the bar.
    assert!(is_dark(c.get(centre(0), y(33.0))));
    assert!(is_dark(c.get(centre(0) + 3, y(35.0))));
    assert!(is_background(c.get(centre(0), y(35.0) - 3)));
    assert!(is_dark(c.get(centre(1), y(-13.5))));
    // No error bar where σ is NaN (j = 7) or zero (j = 9).
    assert!(is_background(c.get(centre(3), y(8.0) - 4)));
    assert!(is_background(c.get(centre(5), y(1.0) - 4)));

    // x tick marks below the frame at whole j only, labelled.
    let below = (y0 + h) as usize + 2;
    let ticks: Vec<usize> = (0..N)
        .filter(|&i| is_dark(c.get(centre(i), below)))
        .collect();
    assert!(ticks.len() >= 4, "{ticks:?}");
    assert!(
        c.ink(x0 as usize, below + 4, w as usize, 20) > 40,
        "x tick labels"
    );
    // y tick labels and the turned axis name left of the frame.
    let y_side = c.ink(
        x0 as usize - Y_AXIS_W as usize,
        y0 as usize,
        Y_AXIS_W as usize - 8,
        h as usize,
    );
    assert!(y_side > 200, "{y_side}");
    let name = c.ink(x0 as usize - Y_AXIS_W as usize, y0 as usize, 28, h as usize);
    assert!(name > 60, "no y axis name: {name}");
    // The title band has text.
    assert!(
        c.ink(0, MARGIN as usize, c.width, TITLE_PX as usize + 4) > 300,
        "title"
    );
}

#[test]
fn many_bars_widen_the_chart() {
    let v: Vec<f64> = (0..231).map(|k| (k as f64 * 0.37).sin() * 40.0).collect();
    let chart = Chart::new(&v, &[], 1, "231 terms").unwrap();
    assert!(chart.size.0 >= 6 * 231, "{:?}", chart.size);
    let c = Pixels::new(chart.size, output::render_rgb(&chart).unwrap());
    let (x0, y0, w, h) = chart.plot;
    // x labels: at most one per 40 pixels, so they never touch.
    let below = (y0 + h) as usize + 2;
    let marks = (x0 as usize..(x0 + w) as usize)
        .filter(|&x| is_dark(c.get(x, below)))
        .count();
    assert!(
        marks >= 5 && marks <= (w / X_LABEL_PITCH) as usize + 1,
        "{marks}"
    );
}

#[test]
fn all_nan_reads_no_data() {
    let v = [f64::NAN; 3];
    let chart = Chart::new(&v, &[], 1, "none").unwrap();
    let c = Pixels::new(chart.size, output::render_rgb(&chart).unwrap());
    let (x0, y0, w, h) = chart.plot;
    let (cx, cy) = ((x0 + w / 2) as usize, (y0 + h / 4) as usize);
    assert!(c.ink(cx - 42, cy - 9, 84, 18) > 20, "no 'no data' note");
}

#[test]
fn svg_holds_the_title_bars_and_error_bars() {
    let (v, s) = coefficients();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("chart.svg");
    let title = "Coefficients (Noll j ≥ 4), ±1σ in nm";
    coefficient_chart_svg(&p, &v, &s, FIRST, title).unwrap();
    let svg = std::fs::read_to_string(&p).unwrap();
    assert!(svg.contains(title), "title");
    assert!(svg.contains("Noll j") && svg.contains("coefficient (nm)"));
    // One filled rect per finite bar in the bar colours.
    assert_eq!(svg.matches("fill=\"#B2182B\"").count(), 18, "positive bars");
    assert_eq!(svg.matches("fill=\"#2166AC\"").count(), 1, "negative bar");
    // Error bars: a stem and two caps each, a ring at each value.
    assert_eq!(svg.matches("<circle").count(), 2, "error bar rings");
}

#[test]
fn bad_input_is_named() {
    let err = Chart::new(&[1.0, 2.0], &[0.1], 1, "t").err().unwrap();
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
    let err = Chart::new(&[], &[], 1, "t").err().unwrap();
    assert!(
        matches!(err, PlotError::Empty { argument: "values" }),
        "{err}"
    );
    let many = vec![0.0; MAX_BARS + 1];
    let err = Chart::new(&many, &[], 1, "t").err().unwrap();
    assert!(matches!(err, PlotError::TooMany { .. }), "{err}");
    for p in ["chart.png", "chart.svg"] {
        let p = Path::new("/nonexistent-dir-for-mfd-test").join(p);
        let err = if p.extension().unwrap() == "png" {
            coefficient_chart_png(&p, &[1.0], &[], 1, "t")
        } else {
            coefficient_chart_svg(&p, &[1.0], &[], 1, "t")
        }
        .unwrap_err();
        assert!(err.to_string().contains(&p.display().to_string()), "{err}");
    }
}
