use super::*;
use crate::plot::test_util::{column, row, Pixels, Rgb, WHITE};

fn panel<'a>(series: &'a [Series<'a>], log: bool) -> Panel<'a> {
    Panel {
        title: "RMS error",
        x_label: "frames",
        y_label: "σ (nm)",
        log_x: log,
        log_y: log,
        series,
    }
}

fn rgb(c: RGBColor) -> Rgb {
    [c.0, c.1, c.2]
}

fn is_background(p: Rgb) -> bool {
    p == WHITE || p == rgb(GRID)
}

fn render<'a>(panels: &'a [Panel<'a>]) -> (Plot<'a>, Pixels) {
    let plot = Plot::new(panels).unwrap();
    let c = Pixels::new(plot.size(), output::render_rgb(&plot).unwrap());
    (plot, c)
}

/// The pixel nearest data point `p` of panel geometry `g`.
fn pixel(c: &Pixels, g: &Geom, p: (f64, f64)) -> Rgb {
    let (x, y) = place(g, p);
    c.get(x, y)
}

fn place(g: &Geom, (x, y): (f64, f64)) -> (usize, usize) {
    let t = (g.x.frac(x), g.y.frac(y));
    let x = column(t.0, (0.0, 1.0), g.plot_x(), PLOT_W);
    (x, row(t.1, (0.0, 1.0), plot_top(), PLOT_H))
}

#[test]
fn written_plot_has_its_size_and_series_colours_at_their_points() {
    let a = [(0.0, 1.0), (4.0, 3.0), (10.0, 2.0)];
    let b = [(1.0, 8.0), (6.0, 7.0)];
    let series = [
        Series {
            label: "a",
            points: &a,
        },
        Series {
            label: "b ± 1σ",
            points: &b,
        },
    ];
    let panels = [panel(&series, false), panel(&series[..1], true)];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lines.png");
    line_plot_png(&path, &panels).unwrap();
    let c = Pixels::read_png(&path);

    let plot = Plot::new(&panels).unwrap();
    let g = &plot.geoms;
    assert_eq!((c.width as u32, c.height as u32), plot.size());
    assert_eq!(c.width as u32, g[1].left + g[1].width);
    assert!(g[0].width >= PLOT_W && g[1].left == g[0].width);
    // Marker centres: a disc for the first series, a square for the second.
    assert_eq!(pixel(&c, &g[0], (4.0, 3.0)), rgb(PALETTE[0]));
    assert_eq!(pixel(&c, &g[0], (6.0, 7.0)), rgb(PALETTE[1]));
    // Halfway along a segment, the line's own colour.
    assert_eq!(pixel(&c, &g[0], (3.5, 7.5)), rgb(PALETTE[1]));
    // The log panel drops x = 0 and draws the rest.
    assert_eq!(pixel(&c, &g[1], (4.0, 3.0)), rgb(PALETTE[0]));
    // Titles in both panels' title bands.
    for p in g {
        assert!(c.ink(p.left as usize, MARGIN as usize, p.width as usize, 26) > 60);
    }
}

#[test]
fn log_axes_place_equal_ratios_at_equal_distances() {
    let pts = [(1.0, 1.0), (10.0, 10.0), (100.0, 100.0)];
    let series = [Series {
        label: "s",
        points: &pts,
    }];
    let panels = [panel(&series, true)];
    let (plot, c) = render(&panels);
    let g = &plot.geoms[0];
    // 1 and 100 are the axis ends, so 10 lies halfway.
    let (x1, y1) = place(g, (1.0, 1.0));
    let (x10, y10) = place(g, (10.0, 10.0));
    assert_eq!(
        (x1, y1),
        (g.plot_x() as usize, (plot_top() + PLOT_H - 1) as usize)
    );
    assert!((x10 - x1) as f64 - 0.5 * f64::from(PLOT_W - 1) <= 1.0);
    assert!((y1 - y10) as f64 - 0.5 * f64::from(PLOT_H - 1) <= 1.0);
    assert_eq!(c.get(x10, y10), rgb(PALETTE[0]));
    // 3 is log10(3) ≈ 0.477 of a decade along, on the line.
    assert_eq!(pixel(&c, g, (3.0, 3.0)), rgb(PALETTE[0]));
}

#[test]
fn nan_and_non_positive_log_points_break_the_line() {
    let with_nan = [(0.0, 0.0), (5.0, f64::NAN), (10.0, 10.0)];
    let unbroken = [(0.0, 0.0), (10.0, 10.0)];
    for (pts, broken) in [(&with_nan[..], true), (&unbroken[..], false)] {
        let series = [Series {
            label: "s",
            points: pts,
        }];
        let panels = [panel(&series, false)];
        let (plot, c) = render(&panels);
        let g = &plot.geoms[0];
        // (5, 5) lies between the NaN's neighbours, on no grid line.
        assert_eq!(is_background(pixel(&c, g, (5.2, 5.2))), broken);
        assert_eq!(pixel(&c, g, (10.0, 10.0)), rgb(PALETTE[0]));
    }
    let with_negative = [(1.0, 1.0), (10.0, -3.0), (50.0, 50.0)];
    let series = [Series {
        label: "s",
        points: &with_negative,
    }];
    let panels = [panel(&series, true)];
    let (plot, c) = render(&panels);
    let g = &plot.geoms[0];
    assert!(is_background(pixel(&c, g, (12.0, 12.0))));
    assert_eq!(pixel(&c, g, (50.0, 50.0)), rgb(PALETTE[0]));
}

#[test]
fn legend_avoids_the_data_and_lists_every_series() {
    // A rising diagonal crosses the top-right and bottom-left corners, so
    // the legend goes top left.
    let pts = [(0.0, 0.0), (10.0, 10.0)];
    let none = [(f64::NAN, 1.0), (2.0, f64::INFINITY)];
    let series = [
        Series {
            label: "rising",
            points: &pts,
        },
        Series {
            label: "none",
            points: &none,
        },
    ];
    let panels = [panel(&series, false)];
    let (plot, c) = render(&panels);
    let g = &plot.geoms[0];
    let border =
        |x: usize, y: usize, w: usize, h: usize| c.count(x, y, w, h, |p| p == rgb(LEGEND_BORDER));
    let (x0, y0) = (g.plot_x() as usize, plot_top() as usize);
    let half = (PLOT_W / 2) as usize;
    let upper_left = border(x0, y0, half, 120);
    let upper_right = border(x0 + half, y0, half, 120);
    assert!(
        upper_left > 100 && upper_right == 0,
        "{upper_left} {upper_right}"
    );
    // The series without finite points has its legend entry: its colour
    // appears only there, as a sample line and a square marker.
    let second = c.count(x0, y0, half, 120, |p| p == rgb(PALETTE[1]));
    assert!(second > 20 && second < 300, "{second}");
}

#[test]
fn empty_panels_read_no_data_and_svg_holds_the_text() {
    let panels = [panel(&[], true)];
    let (plot, c) = render(&panels);
    let g = &plot.geoms[0];
    let (cx, cy) = (
        (g.plot_x() + PLOT_W / 2) as usize,
        (plot_top() + PLOT_H / 4) as usize,
    );
    assert!(c.ink(cx - 42, cy - 9, 84, 18) > 20, "no 'no data' note");

    let pts = [(1.0, 2.0), (10.0, 20.0), (100.0, 50.0)];
    let series = [Series {
        label: "spectral, σ ≥ 0.1 µm",
        points: &pts,
    }];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lines.svg");
    line_plot_svg(&path, &[panel(&series, true)]).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    for text in [
        "RMS error",
        "frames",
        "σ (nm)",
        "spectral, σ ≥ 0.1 µm",
        ">\n100\n</text>",
    ] {
        assert!(svg.contains(text), "{text}");
    }
    assert!(svg.contains("<polyline"), "series lines");
}

#[test]
fn empty_and_overfull_inputs_are_errors() {
    assert!(matches!(
        Plot::new(&[]).err().unwrap(),
        PlotError::Empty { argument: "panels" }
    ));
    let pts = [(1.0, 1.0)];
    let series = vec![
        Series {
            label: "s",
            points: &pts
        };
        MAX_SERIES + 1
    ];
    let err = Plot::new(&[panel(&series, false)]).err().unwrap();
    assert!(matches!(err, PlotError::TooMany { count: 9, .. }), "{err}");
    for p in ["/nonexistent-mfd/x.png", "/nonexistent-mfd/x.svg"] {
        let path = Path::new(p);
        let err = if p.ends_with("png") {
            line_plot_png(path, &[panel(&[], false)])
        } else {
            line_plot_svg(path, &[panel(&[], false)])
        };
        assert!(err.unwrap_err().to_string().contains(p));
    }
}
